"""A person walks out of a 1 m passage straight at the robot standing in its mouth (the patrol's
doorway, issue 39): the Behaviors' give-way sees it in the scan, takes the robot out of the
person's way (backing out, pulling aside) and hands back when the way is clear. The person is the
blind one (it walks on through whatever is in its way), so any contact would be seen. Everything
is measured on the simulator's clock (``sim_status``), not the wall clock, and the recipe runs
under ``emos run --lockstep``, so a busy machine slows the run, not the robot's reactions."""
from __future__ import annotations

import math

import pytest

from emos.core import control
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]

ROBOT_RADIUS, PERSON_RADIUS = 0.2, 0.22


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


RECIPE = """
import numpy as np
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person
from emos.actors.sim.primitives import Wall
from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
from emos.actors.nav.recovery import GiveWayConfig

# A 1 m passage from x = 0.6 to 14 (walls at y = +-0.55, 0.1 m thick); the robot stands in its
# mouth facing in; a person walks out of it from x = 13.5 (about 30 simulated s away) into the room.
person = Person(waypoints=np.array([[13.5, 0.0], [-3.0, 0.0]]), speed=0.4, mode="once")
sim = Simulator("sim", config=SimulatorConfig(world="empty", spawn=(0.8, 0.0, 0.0), scan_range_max=8.0,
                                             obstacles=[Wall((0.6, 0.55), (14.0, 0.55), 0.1), Wall((0.6, -0.55), (14.0, -0.55), 0.1)],
                                             moving_obstacles=[person]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=Topic(name="/odom", msg_type="Odometry"), scan=Topic(name="/scan", msg_type="LaserScan"))
robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.2, 0.3]))
behaviors = Behaviors("behaviors", config=BehaviorsConfig(max_rotational_vel=1.0, give_way=GiveWayConfig(enabled=True)))
behaviors.inputs(sensor_data=Topic(name="/scan", msg_type="LaserScan"), location=Topic(name="/odom", msg_type="Odometry"))
behaviors.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
launcher = Launcher(multi_processing=True)
launcher.robot = robot
launcher.add_pkg(components=[sim, behaviors])
launcher.bringup()
"""


def test_the_robot_gives_way_to_a_person_walking_at_it_out_of_a_passage(tmp_path):
    system = SystemUnderTest(tmp_path, RECIPE, args=["--lockstep"]).wait_up(components=["sim", "behaviors"], timeout=120)
    sim = control.ControlClient("sim", system.ctx, timeout=10.0)
    behaviors = control.ControlClient("behaviors", system.ctx, timeout=10.0)
    try:
        def gap(status):
            (rx, ry), (px, py) = status["pose"][:2], status["movers"][0]["pose"][:2]
            return math.hypot(px - rx, py - ry) - ROBOT_RADIUS - PERSON_RADIUS

        wait_until(lambda: behaviors.execute_method("stats") is not None, 60, what="the behaviors' stats")
        start = sim.execute_method("sim_status")
        assert start["movers"][0]["pose"][0] > 2.8, f"the person was out of the passage before the system was up: {start}"
        t0, least, st = start["sim_time"], math.inf, start
        # Until the person is past the robot's start and out in the room (x < -1.5), 60 simulated s at most.
        while st["sim_time"] - t0 < 60.0 and st["movers"][0]["pose"][0] > -1.5:
            least = min(least, gap(st))
            st = wait_until(lambda: sim.execute_method("sim_status"), 30, what="sim_status")
        log = system.log_path.read_text(errors="replace")
        assert least > 0.0, f"the person touched the robot (least gap {least:.3f} m)\n" + log[-3000:]
        assert st["movers"][0]["pose"][0] <= -1.5, "the person did not get past within 60 simulated s"
        assert "give_way started" in log and ("give_way: back_out" in log or "give_way: pull_aside" in log), log[-3000:]
        wait_until(lambda: "give_way done: the way is clear" in system.log_path.read_text(errors="replace"), 60,
                   what="the give-way handing back once the person is past")
        stats = behaviors.execute_method("stats")
        assert stats["give_way"] >= 1 and stats["succeeded"] >= 1, stats
    finally:
        assert system.stop() == 0
