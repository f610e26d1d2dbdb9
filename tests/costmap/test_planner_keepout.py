"""The Planner on a global costmap, on the component harness: plans go round a keepout zone,
a keepout start or goal is a planning failure naming the zone, the costmap is published, the
smoother runs on the plan. (test_costmap_processes.py runs MapServer + Planner as processes.)"""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from emos.testing import ComponentHarness

from .helpers import KEEPOUT, room_grid, write_room

pytestmark = pytest.mark.unit


def _planner(keepout: str, **extra):
    from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
    from emos.actors.nav.components import Planner, PlannerConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.15, 0.3]),
                        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
    config = PlannerConfig(loop_rate=1.0, planner_id="CostToGo", robot=robot, frames=RobotFrames(world="map", odom="map"),
                           costmap={"enabled": True, "keepout_mask": keepout}, **extra)
    return Planner(component_name="planner", config=config)


def _odom(x: float, y: float) -> M.Odometry:
    odom = M.Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
    odom.pose.pose.orientation = M.Quaternion.from_yaw(0.0)
    return odom


def _goal(x: float, y: float) -> M.PointStamped:
    return M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=x, y=y))


def _path(msg) -> np.ndarray:
    return np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses])


def _status(h: ComponentHarness):
    return h.health


def test_plan_goes_round_keepout_and_keepout_start_or_goal_fails_naming_the_zone(tmp_path):
    from emos.actors.nav.components.convert import grid_msg
    from emos.core.health import HealthLevel

    _, keepout = write_room(tmp_path)
    room = room_grid()
    with ComponentHarness(_planner(keepout, smoother={"enabled": True}), tick=0.1) as h:
        h.feed("/map", grid_msg(room.data, room.resolution, room.origin, "map"))
        h.feed("/odom", _odom(1.0, 1.0))
        h.feed("/goal", _goal(4.5, 1.0))
        h.advance(1.0)
        plan = _path(h.wait_for(lambda: h.latest("/plan"), what="a plan round the keepout zone"))
        assert np.allclose(plan[0], (1.0, 1.0), atol=0.05) and np.allclose(plan[-1], (4.5, 1.0), atol=0.05)
        assert not KEEPOUT.contains(plan).any(), "the plan enters the keepout zone"
        assert plan[:, 1].max() > 2.8  # round the zone's top end
        costmap = h.wait_for(lambda: h.latest("/global_costmap/costmap"), what="the published global costmap")
        cells = np.asarray(costmap.data).reshape(costmap.info.height, costmap.info.width)
        assert cells[int(1.0 / 0.05), int(3.0 / 0.05)] == 100  # keepout: lethal
        assert cells[int(1.0 / 0.05), int(0.15 / 0.05)] == 99  # beside the wall: inscribed

        h.feed("/goal", _goal(3.0, 1.5))  # the goal inside the zone
        h.advance(1.0)
        st = h.wait_for(lambda: (s := _status(h)) is not None and "keepout" in s.message and s, what="goal-in-keepout failure")
        assert st.level == HealthLevel.ALGORITHM_FAILURE
        assert "the goal (3.00, 1.50) is inside keepout zone 'wet_floor' (keepout.yaml)" in st.message

        h.feed("/odom", _odom(3.2, 0.5))  # the robot was pushed into the zone
        h.feed("/goal", _goal(1.0, 3.0))
        h.advance(1.0)
        st = h.wait_for(lambda: (s := _status(h)) is not None and "the start" in s.message and s, what="start-in-keepout failure")
        assert st.level == HealthLevel.ALGORITHM_FAILURE and "keepout zone 'wet_floor'" in st.message


def test_a_goal_that_arrives_while_a_query_runs_is_planned_when_it_ends_without_waiting_a_period(tmp_path):
    """The step that takes a new goal finds the worker busy with the old one: the new goal is
    planned as soon as that query ends, not a period (here 1 s of robot time) later. The clock
    stays stopped while the test waits, so only the worker can plan it."""
    import threading

    from emos.actors.nav.components.convert import grid_msg

    _, keepout = write_room(tmp_path)
    room = room_grid()
    planner = _planner(keepout)
    release, first = threading.Event(), threading.Event()
    plan_once = planner.plan_once

    def slow_first_query(goal, **kwargs):
        if not first.is_set():
            first.set()
            release.wait(60)  # the first query runs until the test lets it end
        return plan_once(goal, **kwargs)

    planner.plan_once = slow_first_query
    with ComponentHarness(planner, tick=0.1) as h:
        h.feed("/map", grid_msg(room.data, room.resolution, room.origin, "map"))
        h.feed("/odom", _odom(1.0, 1.0))
        h.feed("/goal", _goal(4.5, 1.0))
        h.advance(1.0)
        h.wait_for(first.is_set, what="the first query running")
        h.feed("/goal", _goal(1.0, 3.0))
        h.advance(1.0)  # the step that takes the new goal: the worker is busy
        release.set()
        plan = _path(h.wait_for(lambda: (p := h.latest("/plan")) is not None and np.allclose(_path(p)[-1], (1.0, 3.0), atol=0.05) and p,
                                timeout=30, what="a plan to the second goal"))
        assert np.allclose(plan[0], (1.0, 1.0), atol=0.05)
