"""The Planner, as a real process, taking Detections / PointsOfInterest goals with depth: a good
one becomes a plan to the point it shows (PointsOfInterest: tests/nav/test_nav_pixel_goals.py); each bad one (no camera info, no depth image, NaN
depth, no detection, no transform to the camera) is reported naming the topic at fault, and the
current goal is kept."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.agents.components_helpers import Probe
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = [pytest.mark.sim, pytest.mark.process]

GOAL_TOPIC = "/grounding_output"
INFO_TOPIC = "/camera/aligned_depth_to_color/camera_info"  # the Planner's default depth_camera_info
W, H, F = 160, 120, 100.0  # image size and focal length (px)
ROBOT = (1.0, 1.0, math.pi / 2)  # facing +y
CAMERA_XYZ = (0.2, 0.0, 0.4)  # on the base: 0.2 m ahead, 0.4 m up


def _depth(z: float, frame: str = "camera/depth") -> M.Image:
    return M.Image.from_numpy(np.full((H, W), z, np.float32), encoding="32FC1", header=M.Header(frame_id=frame))


def _detections(box, depth: M.Image | None) -> M.Detections:
    return M.Detections(scores=np.ones(1), labels=["person"], boxes=np.array([box], float), image=depth)


def _setup_messages():
    from emos.actors.sim.component.publishing import quaternion_from_matrix

    free = M.OccupancyGrid(header=M.Header(frame_id="map"),
                           info=M.MapMetaData(resolution=0.1, width=100, height=100,
                                              origin=M.Pose(position=M.Point(x=-2.0, y=-2.0))),
                           data=np.zeros(100 * 100, np.int8))
    odom = M.Odometry(header=M.Header(frame_id="odom"),
                      pose=M.PoseWithCovariance(pose=M.Pose(position=M.Point(x=ROBOT[0], y=ROBOT[1]),
                                                            orientation=M.Quaternion.from_yaw(ROBOT[2]))))
    q = quaternion_from_matrix(np.c_[[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # optical frame
    tf = M.TFMessage(transforms=[M.TransformStamped(
        header=M.Header(frame_id="base_link"), child_frame_id="camera/depth",
        transform=M.Transform(translation=M.Vector3(x=CAMERA_XYZ[0], y=CAMERA_XYZ[1], z=CAMERA_XYZ[2]),
                              rotation=M.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])))])
    info = M.CameraInfo.from_intrinsics(W, H, F, F, (W - 1) / 2, (H - 1) / 2)
    return free, odom, tf, info


def test_planner_turns_a_detection_with_depth_into_a_goal_and_keeps_it_on_bad_input(tmp_path):
    system = SystemUnderTest(tmp_path, f"""
from emos.actors.nav.components import Planner, PlannerConfig
planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=4.0, planner_id="CostToGo"))
planner.inputs(goal_point=Topic(name="{GOAL_TOPIC}", msg_type="Detections"))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[planner], multiprocessing=True)
launcher.bringup()
""", env={"PYTHONPATH": str(REPO)}, duration=120).wait_up(timeout=60, components=["planner"])
    probe = Probe(system)
    free, odom, tf, info = _setup_messages()
    statuses = probe.sub("/planner/status", "ComponentStatus")
    plans = probe.sub("/plan", "Path")

    def failure(topic: str, text: str) -> M.ComponentStatus:
        def found():
            probe.pub("/odom", odom)
            return next((s for s in statuses.take() if s.status == HealthLevel.SYSTEM_FAILURE and text in s.message), None)

        status = wait_until(found, 15, interval=0.1, what=f"a SYSTEM failure saying {text!r}")
        assert status.src_topics == [topic], status
        return status

    def plan_end() -> tuple[float, float]:
        def latest():
            probe.pub("/odom", odom)
            got = plans.take()
            return got[-1] if got and len(got[-1].poses) else None

        end = wait_until(latest, 15, interval=0.1, what="a plan").poses[-1].pose.position
        return end.x, end.y

    try:
        for topic, msg in (("/map", free), ("/odom", odom), ("/tf", tf)):
            probe.pub(topic, msg)
        # A box 20 px left of the image centre at 2 m: 0.4 m left of the camera's axis; the
        # robot faces +y, so the goal is 2.2 m up and 0.4 m left (-x) of the robot.
        cx, cy = (W - 1) / 2, (H - 1) / 2
        good = [cx - 20 - 5, cy - 10, cx - 20 + 5, cy + 10]
        expected = (ROBOT[0] - 0.4, ROBOT[1] + CAMERA_XYZ[0] + 2.0)
        probe.pub(GOAL_TOPIC, _detections(good, _depth(2.0)))  # before any camera info
        failure(INFO_TOPIC, "no CameraInfo received yet")
        assert plans.take() == []
        probe.pub(INFO_TOPIC, info)
        probe.pub(GOAL_TOPIC, _detections(good, _depth(2.0)))
        end = plan_end()
        assert math.dist(end, expected) < 0.05, (end, expected)
        bad_inputs = [
            (_detections(good, None), GOAL_TOPIC, "carries no depth image"),
            (_detections(good, _depth(math.nan)), GOAL_TOPIC, "no valid depth"),
            (M.Detections(scores=np.zeros(0), labels=[], boxes=np.zeros((0, 4))), GOAL_TOPIC, "holds no detection"),
            (_detections(good, _depth(2.0, frame="elsewhere")), "/tf", "no transform from 'base_link' to the camera frame 'elsewhere'"),
        ]
        for msg, topic, text in bad_inputs:
            probe.pub(GOAL_TOPIC, msg)
            status = failure(topic, text)
            assert "the current goal is kept" in status.message
            plans.take()
            assert math.dist(plan_end(), expected) < 0.05  # still planning to the good goal
        out = system.output()
        assert f"[planner] goal_point {GOAL_TOPIC} (Detections): the message carries no depth image" in out
        assert "[planner] no CameraInfo received yet" not in out  # the topic is named first:
        assert f"[planner] depth_camera_info {INFO_TOPIC}: no CameraInfo received yet" in out
    finally:
        probe.close()
        assert system.stop() == 0
