"""The navigation components as real processes under the supervisor, closing the loop through
a kinematic base: drive to a goal, survive a SIGKILLed controller, stop on stale odometry. The
Planner's path files and recording are tested on the component harness in
test_planner_on_harness.py."""
from __future__ import annotations

import math
import os
import signal
import time

import pytest

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

STACK = """
from emos.actors.nav import RobotConfig, RobotType, RobotGeometry, LinearCtrlLimits, AngularCtrlLimits, RobotFrames
from emos.actors.nav.components import (Controller, ControllerConfig, DriveManager, DriveManagerConfig, LocalMapper,
    LocalMapperConfig, MapServer, MapServerConfig, Planner, PlannerConfig, TopicsKeys)
from emos.actors.nav import MapConfig
from tests.nav.components.fake_base import FakeBase

robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.15, 0.3]),
                    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                    ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0, planner_id="CostToGo"))
controller = Controller(component_name="controller", config=ControllerConfig(loop_rate=10.0))
controller.algorithm = "PurePursuit"
controller.direct_sensor = False
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.2))
mapper = LocalMapper(component_name="mapper", config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path=MAP_FILE))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.0))])
launcher.kompass(components=[map_server, planner, controller, driver, mapper], multiprocessing=True)
launcher.inputs(location=Topic(name="/odom", msg_type="Odometry"))
launcher.robot = robot
launcher.frames = RobotFrames(world="map", odom="map")
launcher.bringup()
"""

COMPONENTS = ["base", "map_server", "planner", "controller", "driver", "mapper"]


def _start(tmp_path, freeze) -> SystemUnderTest:
    from tests.nav.components.fake_base import write_room_map

    map_file = write_room_map(tmp_path / "room.yaml")
    body = f"MAP_FILE = {map_file!r}\n" + STACK
    env = {"PYTHONPATH": str(REPO), "FAKE_BASE_FREEZE_ODOM": str(freeze)}
    return SystemUnderTest(tmp_path, body, env=env).wait_up(timeout=60, components=COMPONENTS)


def _sub(system, name, msg_type):
    from emos.transport.pubsub import Subscriber

    return Subscriber(system.ctx, name, msg_type, queue_size=50)


def _latest(sub):
    items = sub.take()
    return items[-1] if items else None


def _status(sub):
    msg = None
    for m in sub.take():
        msg = m
    return msg


def _goal(x, y):
    return M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=x, y=y))


def test_stack_drives_to_goal_survives_controller_kill_and_stops_on_stale_odometry(tmp_path):
    from emos.transport.pubsub import Publisher

    freeze = tmp_path / "freeze_odom"
    system = _start(tmp_path, freeze)
    odom, cmd, reached = _sub(system, "/odom", M.Odometry), _sub(system, "/cmd_vel", M.Twist), _sub(system, "/reached_end", M.Bool)
    planner_status = _sub(system, "/planner/status", M.ComponentStatus)
    driver_status = _sub(system, "/driver/status", M.ComponentStatus)
    goal_pub = Publisher(system.ctx, "/goal", M.PointStamped, publisher_id="test_goal")
    try:
        # 1. A goal behind the wall: the robot goes round it. Kill the controller on the way.
        goal_pub.publish(_goal(4.5, 1.0))
        wait_until(lambda: (m := _latest(cmd)) is not None and m.linear.x > 0.1, 30, what="the robot to drive")
        old_pid = system.pid("controller")
        os.kill(old_pid, signal.SIGKILL)
        killed_at = time.monotonic()
        # The DriveManager (the only publisher of /cmd_vel) stops the robot; the wait bounds a hang.
        wait_until(lambda: (m := _latest(cmd)) is not None and m.linear.x == 0.0 and m.angular.z == 0.0, 30,
                   interval=0.005, what="the DriveManager to stop the robot after the controller died")
        stop_after = time.monotonic() - killed_at
        print(f"controller SIGKILL -> zero command seen after {stop_after * 1e3:.0f} ms")
        system.wait_new_pid("controller", old_pid, timeout=15)

        def arrived():
            return any(m.data for m in reached.take())

        wait_until(arrived, 60, what="reached_end after the controller restart")
        o = _latest(odom) or wait_until(lambda: _latest(odom), 30)
        assert math.hypot(o.pose.pose.position.x - 4.5, o.pose.pose.position.y - 1.0) < 0.4

        # 2. A goal inside the wall and one off the map: ALGORITHM failures that say why.
        goal_pub.publish(_goal(3.0, 1.0))
        st = wait_until(lambda: (s := _status(planner_status)) is not None and s.status == HealthLevel.ALGORITHM_FAILURE and s, 15,
                        what="planner ALGORITHM failure for a goal in an obstacle")
        assert "INVALID_GOAL" in st.message
        goal_pub.publish(_goal(40.0, 1.0))
        st = wait_until(lambda: (s := _status(planner_status)) is not None and "outside the map" in s.message and s, 15,
                        what="planner failure for a goal off the map")
        assert st.status == HealthLevel.ALGORITHM_FAILURE

        # 3. Odometry stops: the DriveManager stops the robot and reports a SYSTEM failure.
        goal_pub.publish(_goal(1.0, 3.0))
        wait_until(lambda: (m := _latest(cmd)) is not None and abs(m.linear.x) + abs(m.angular.z) > 0.05, 20, what="driving again")
        freeze.touch()
        st = wait_until(lambda: (s := _status(driver_status)) is not None and s.status == HealthLevel.SYSTEM_FAILURE and s, 30,
                        what="DriveManager SYSTEM failure on stale odometry")
        assert "/odom" in st.src_topics
        time.sleep(0.3)
        cmds = cmd.take()
        assert cmds and all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds[-3:])
    finally:
        goal_pub.close()
        for s in (odom, cmd, reached, planner_status, driver_status):
            s.close()
        system.stop()
