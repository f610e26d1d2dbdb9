"""DockingServer in a real System with the Simulator: a dock that is not there fails with the
reason and the robot stopped; the real dock is found in the scan and docked on; undock backs off."""
from __future__ import annotations

import math

import pytest

from emos import msgs as M
from emos.core.services import ActionClient
from emos.transport.pubsub import Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


RECIPE = """
import math
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.builders import charging_dock
from emos.actors.sim.primitives import Wall
from emos.actors.nav.components.docking import DockingServer, DockingServerConfig

DOCK = (0.0, 0.0, 0.0)
walls = [Wall((-0.3, -2), (-0.3, 2), 0.1), Wall((-0.3, 2), (3.0, 2), 0.1), Wall((-0.3, -2), (3.0, -2), 0.1)]
sim = Simulator("sim", config=SimulatorConfig(world="empty", robot="turtlebot3_waffle_pi", spawn=(1.02, 0.08, math.pi - 0.2),
                                             obstacles=charging_dock(DOCK) + walls, scan_range_max=3.5))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=Topic(name="/odom", msg_type="Odometry"), scan=Topic(name="/scan", msg_type="LaserScan"))
docking = DockingServer("docking", config=DockingServerConfig(docks={"home": DOCK, "ghost": (1.0, 1.5, -math.pi / 2)},
                                                              search_timeout=2.0))
docking.inputs(sensor_data=Topic(name="/scan", msg_type="LaserScan"), location=Topic(name="/odom", msg_type="Odometry"))
docking.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim, docking])
launcher.bringup()
"""


def test_dock_not_found_fails_and_stops_then_docks_and_undocks(tmp_path):
    from emos.actors.nav.components.mission_interfaces import DockRobotFeedback, DockRobotGoal, DockRobotResult, UndockRobotGoal

    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["sim", "docking"], timeout=120)
    odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=5)
    try:
        dock = ActionClient("docking/dock_robot", DockRobotGoal, DockRobotFeedback, DockRobotResult, ctx=system.ctx)
        # Bad input: no dock where the database says ("ghost"): the goal fails, naming why.
        result = dock.send_goal(DockRobotGoal(dock_id="ghost"), timeout=300)
        assert not result.success
        assert "dock 'ghost' not found in the scan within 2 s" in result.message and "robot stopped" in result.message
        last = odom.take()[-1]
        assert abs(last.twist.twist.linear.x) < 1e-3 and abs(last.twist.twist.angular.z) < 1e-3
        # The real dock: found and docked on.
        result = dock.send_goal(DockRobotGoal(dock_id="home"), timeout=600)
        assert result.success, result.message
        pose = odom.take()[-1].pose.pose
        assert math.hypot(pose.position.x - 0.35, pose.position.y) < 0.03, (pose.position.x, pose.position.y)
        assert abs(math.degrees(math.remainder(pose.orientation.yaw() - math.pi, 2 * math.pi))) < 3.0
        undock = ActionClient("docking/undock_robot", UndockRobotGoal, DockRobotFeedback, DockRobotResult, ctx=system.ctx)
        result = undock.send_goal(UndockRobotGoal(), timeout=600)
        assert result.success, result.message
        assert odom.take()[-1].pose.pose.position.x > 0.8
    finally:
        odom.close()
        assert system.stop() == 0
