"""Behaviors (Nav2's behavior server) in a real System with the Simulator: back_up refuses with
the wall behind (naming the gap), spin and drive_on_heading move the robot by what was asked,
clear_costmaps empties the LocalMapper's grid."""
from __future__ import annotations

import math

import pytest

from emos import msgs as M
from emos.core import control
from emos.core.services import ActionClient
from emos.transport.pubsub import Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


RECIPE = """
import math
import numpy as np
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.primitives import Wall
from emos.actors.nav import RobotConfig, RobotGeometry, RobotType, MapConfig
from emos.actors.nav.components import LocalMapper, LocalMapperConfig
from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig

# The robot's back (0.14 m behind its centre) is 0.12 m from a wall.
sim = Simulator("sim", config=SimulatorConfig(world="empty", robot="turtlebot3_waffle_pi", spawn=(0.0, 0.0, 0.0),
                                             obstacles=[Wall((-0.31, -1.0), (-0.31, 1.0), 0.1)], scan_range_max=3.5))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=Topic(name="/odom", msg_type="Odometry"), scan=Topic(name="/scan", msg_type="LaserScan"))
robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.BOX,
                    geometry_params=np.array([0.281, 0.306, 0.141]))
behaviors = Behaviors("behaviors", config=BehaviorsConfig(robot=robot, local_mapper="mapper"))
behaviors.inputs(sensor_data=Topic(name="/scan", msg_type="LaserScan"), location=Topic(name="/odom", msg_type="Odometry"))
behaviors.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
mapper = LocalMapper("mapper", config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))
mapper.inputs(sensor_data=Topic(name="/scan", msg_type="LaserScan"), location=Topic(name="/odom", msg_type="Odometry"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim, behaviors, mapper])
launcher.bringup()
"""


def test_back_up_refuses_with_the_wall_behind_spin_and_drive_move(tmp_path):
    from emos.actors.nav.components.mission_interfaces import BackUpGoal, BehaviorFeedback, BehaviorResult, DriveOnHeadingGoal, SpinGoal

    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["sim", "behaviors", "mapper"], timeout=120)
    odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=5)

    def client(name, goal):
        return ActionClient(f"behaviors/{name}", goal, BehaviorFeedback, BehaviorResult, ctx=system.ctx)

    try:
        wait_until(lambda: odom.take(), 60, what="odometry")

        def back_up_seeing():  # the Behaviors component may not have its first scan yet: ask again
            answer = client("backup", BackUpGoal).send_goal(BackUpGoal(distance=0.3, speed=0.1), timeout=120)
            return None if "no scan" in answer.message else answer

        result = wait_until(back_up_seeing, 60, interval=0.5, what="a back-up answer from a component that has a scan")
        assert not result.success
        assert result.message.startswith("back_up refused: obstacle 0.1"), result.message  # ~0.12 m (scan resolution)
        result = client("spin", SpinGoal).send_goal(SpinGoal(target_yaw=math.pi / 2), timeout=300)
        assert result.success, result.message
        yaw = odom.take()[-1].pose.pose.orientation.yaw()
        assert abs(yaw - math.pi / 2) < math.radians(5), math.degrees(yaw)
        result = client("drive_on_heading", DriveOnHeadingGoal).send_goal(DriveOnHeadingGoal(distance=0.3, speed=0.15), timeout=300)
        assert result.success, result.message
        p = odom.take()[-1].pose.pose.position
        assert abs(p.y - 0.3) < 0.05 and abs(p.x) < 0.05, (p.x, p.y)
        # clear_costmaps as an event action would call it: a component method, in its process.
        assert control.ControlClient("behaviors", system.ctx, timeout=30.0).execute_method("clear_costmaps") is True
        wait_until(lambda: "[mapper] local grid cleared" in system.log_path.read_text(errors="replace"), 30, what="the mapper's clear")
    finally:
        odom.close()
        assert system.stop() == 0
