"""The Controller's track_vision_target action in a real process: it turns towards the target
in the detections and ends (ALGORITHM failure) when the target is gone and search is off."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPE = """
from emos.actors.nav.components import Controller, ControllerConfig
from emos.actors.nav.controllers import VisionRGBFollowerConfig
controller = Controller(component_name="my_controller", config=ControllerConfig(loop_rate=10.0, ctrl_publish_type="Sequence", control_time_step=0.3))
controller.inputs(vision_tracking=Topic(name="/detections", msg_type="Detections"),
                  depth_camera_info=Topic(name="/camera_info", msg_type="CameraInfo"))
controller.algorithm = "VisionRGBFollower"
controller.algorithms_config = VisionRGBFollowerConfig(control_horizon=3, enable_search=False, target_search_pause=6, tolerance=0.2)
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[controller], multiprocessing=True)
launcher.bringup()
"""


def test_track_vision_target_turns_to_the_target_and_fails_when_it_is_lost(tmp_path):
    from emos.actors.nav.components.interfaces import TrackVisionTargetFeedback, TrackVisionTargetGoal, TrackVisionTargetResult
    from emos.core.services import ActionClient
    from emos.transport.pubsub import Publisher, Subscriber

    system = SystemUnderTest(tmp_path, RECIPE, env={"PYTHONPATH": str(REPO)}).wait_up(timeout=60, components=["my_controller"])
    det_pub = Publisher(system.ctx, "/detections", M.Detections, publisher_id="test_vision")
    info_pub = Publisher(system.ctx, "/camera_info", M.CameraInfo, publisher_id="test_info")
    cmd = Subscriber(system.ctx, "/control", M.Twist, queue_size=100)
    status = Subscriber(system.ctx, "/my_controller/status", M.ComponentStatus, queue_size=100)
    client = ActionClient("my_controller/track_vision_target", TrackVisionTargetGoal, TrackVisionTargetFeedback, TrackVisionTargetResult, ctx=system.ctx)
    visible = threading.Event()
    visible.set()
    stop = threading.Event()

    def camera() -> None:  # a person right of the image centre, while "visible"
        while not stop.is_set():
            info_pub.publish(M.CameraInfo.from_intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0))
            if visible.is_set():
                det_pub.publish(M.Detections(scores=np.array([0.9, 0.8]), labels=["chair", "person"],
                                             boxes=np.array([[10.0, 10.0, 60.0, 90.0], [450.0, 150.0, 550.0, 400.0]])))
            time.sleep(0.05)

    feeder = threading.Thread(target=camera, daemon=True)
    feeder.start()
    result: dict = {}
    runner = threading.Thread(target=lambda: result.setdefault("r", client.send_goal(TrackVisionTargetGoal(label="person"), timeout=60)), daemon=True)
    try:
        runner.start()
        turning = wait_until(lambda: [c for c in cmd.take() if c.angular.z < -0.05], 15, what="commands turning right, towards the person")
        assert all(abs(c.linear.x) < 1e-9 for c in turning[:1])  # the box has its reference size: no approach
        # A second goal preempts the first (one loop drives the robot, not two)
        second = threading.Thread(target=lambda: result.setdefault("r2", client.send_goal(TrackVisionTargetGoal(label="person"), timeout=60)), daemon=True)
        second.start()
        runner.join(15)
        assert "r" in result and not result["r"].success and "preempted" in result["r"].message
        wait_until(lambda: [c for c in cmd.take() if c.angular.z < -0.05], 15, what="the second goal turning the robot")
        visible.clear()  # the person leaves the image
        second.join(30)
        assert "r2" in result and not result["r2"].success and "lost" in result["r2"].message
        wait_until(lambda: any(s.status == HealthLevel.ALGORITHM_FAILURE and "lost" in s.message for s in status.take()), 30,
                   what="ALGORITHM failure naming the lost target")
        last = wait_until(lambda: next(iter(cmd.take()[-1:]), None), 30, what="a final command")
        assert last.linear.x == 0.0 and last.angular.z == 0.0
    finally:
        stop.set()
        feeder.join(2)
        client.close() if hasattr(client, "close") else None
        for x in (det_pub, info_pub, cmd, status):
            x.close()
        system.stop()
