"""The Planner's path files and path recording, on the component harness (no process tree): a
plan is saved, the robot's driven path recorded on robot time, a file loaded as the plan. The
Planner's process wiring is tested with the whole stack in test_nav_stack_processes.py."""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit


def _planner():
    from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
    from emos.actors.nav.components import Planner, PlannerConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.15, 0.3]),
                        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
    return Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0, planner_id="CostToGo", robot=robot,
                                                                    frames=RobotFrames(world="map", odom="map")))


def _odom(x: float, y: float) -> M.Odometry:
    odom = M.Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
    odom.pose.pose.orientation = M.Quaternion.from_yaw(0.0)
    return odom


def test_planner_saves_loads_and_records_paths(tmp_path):
    from emos.actors.nav.components.convert import grid_msg
    from emos.actors.nav.components.interfaces import PathFromToFileRequest, StartPathRecordingRequest
    from emos.actors.nav.maps import load_map
    from tests.nav.components.fake_base import write_room_map

    room = load_map(write_room_map(tmp_path / "room.yaml"))

    def path_file(name: str) -> PathFromToFileRequest:
        return PathFromToFileRequest(file_location=str(tmp_path), file_name=name)

    with ComponentHarness(_planner(), tick=0.1) as h:
        h.feed("/map", grid_msg(room.data, room.resolution, room.origin, "map"))
        h.feed("/odom", _odom(1.0, 1.0))
        bad = h.call("planner/save_plan_to_file", path_file("early.csv"))
        assert not bad.success and "no plan" in bad.message
        h.feed("/goal", M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=4.5, y=1.0)))
        h.advance(1.0)  # a planning period: the plan is computed on the Planner's worker thread
        h.wait_for(lambda: h.latest("/plan"), what="plan to (4.5, 1.0)")
        ok = h.call("planner/save_plan_to_file", path_file("computed.csv"))
        assert ok.success, ok.message
        rows = (tmp_path / "computed.csv").read_text().splitlines()
        assert rows[0] == "x,y,yaw" and len(rows) > 20
        assert h.call("planner/start_path_recording", StartPathRecordingRequest(recording_time_step=0.1)).success
        x = 1.0

        def drive(h: ComponentHarness) -> None:  # the robot drives east at 0.2 m/s
            nonlocal x
            x += 0.2 * h.tick
            h.feed("/odom", _odom(x, 1.0))

        h.advance(2.0, each_tick=drive)
        rec = h.call("planner/save_plan_to_file", path_file("driven.csv"))
        assert rec.success and "recorded path" in rec.message, rec.message
        driven = np.loadtxt(tmp_path / "driven.csv", delimiter=",", skiprows=1)
        assert len(driven) >= 5 and np.hypot(*(driven[-1, :2] - driven[0, :2])) > 0.2  # the robot moved meanwhile
        missing = h.call("planner/load_plan_from_file", path_file("nope.csv"))
        assert not missing.success and "nope.csv" in missing.message
        h.outputs("/plan")
        loaded = h.call("planner/load_plan_from_file", path_file("driven.csv"))
        assert loaded.success, loaded.message
        # Published by the service at once; the Planner's worker, still planning to the goal,
        # may publish its own plan beside it (a busy machine: a failure in a loaded suite run).
        plans = [np.array([(p.pose.position.x, p.pose.position.y) for p in m.poses]) for m in h.outputs("/plan")]
        assert any(xy.shape == (len(driven), 2) and np.allclose(xy, driven[:, :2], atol=1e-6) for xy in plans), \
            [xy.shape for xy in plans]
