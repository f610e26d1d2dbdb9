"""Lockstep with the stack's compute time charged (``SimulatorConfig.compute_deadline``): a
command acts only after the CPU time the consumers spent on its tick, and ticks charged more
than the deadline are counted as misses."""
from __future__ import annotations

import math

import pytest

from emos import msgs as M
from emos.actors.sim.component.compute_charge import ComputeCharge
from emos.transport.pubsub import Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytestmark = [pytest.mark.sim, pytest.mark.process]


def test_charge_sums_the_reports_of_a_tick_and_counts_misses():
    charge = ComputeCharge(deadline_s=0.1, physics_dt=0.01)
    charge.report("mapper", 0.004)
    charge.report("controller", 0.021)
    assert charge.close_tick() == 3  # 25 ms of one core: the command waits 3 physics ticks
    assert charge.close_tick() == 0  # a tick with nothing reported costs nothing
    charge.report("controller", 0.15)
    assert charge.close_tick() == 15
    for bad in (float("nan"), -1.0, math.inf, "x", True):
        charge.report("foreign", bad)  # not charged, counted
    assert charge.close_tick() == 0
    stats = charge.stats()
    assert stats["deadline_misses"] == 1 and stats["charged_ticks"] == 4 and stats["bad_reports"] == 5
    assert stats["compute_worst_s"] == pytest.approx(0.15)


def test_a_newer_command_that_acts_supersedes_older_held_ones():
    charge = ComputeCharge(deadline_s=0.1, physics_dt=0.01)
    charge.hold("slow", 10)  # computed first but charged long
    charge.hold("fast", 5)
    assert charge.due(4) is None
    assert charge.due(5) == "fast"
    assert charge.due(10) is None  # the older command never acts after the newer one


pybullet = pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

# From simulated t = 1 s the driver commands 1 m/s, and each of its steps burns BURN_S of CPU.
RECIPE = """
from emos.actors.sim import Simulator, SimulatorConfig
from emos.core import clock
from emos.config import BaseComponentConfig

BURN_S = 0.06

class Driver(BaseComponent):
    def _execution_step(self):
        if clock.now() < 1.0 - 1e-6:
            self.publish("/cmd_vel", M.Twist())
        else:
            cpu0 = time.thread_time()
            while time.thread_time() - cpu0 < BURN_S:
                pass
            with open("commanded.txt", "a") as f:
                f.write(f"{clock.now():.3f}\\n")
            self.publish("/cmd_vel", M.Twist(linear=M.Vector3(x=1.0)))
        self.health_status.set_healthy()

driver = Driver("driver", outputs=[Topic(name="/cmd_vel", msg_type="Twist")],
                config=BaseComponentConfig(loop_rate=10.0, use_sim_time=True))
sim = Simulator("sim", config=SimulatorConfig(world="house", robot="jackal", clock_mode="lockstep", drive="ideal",
                                             lockstep_consumers=["driver"], compute_deadline=0.05))
launcher = Launcher(multi_processing=True, heartbeat_timeout=30.0)
launcher.add_pkg(components=[sim, driver])
launcher.bringup()
"""


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


def test_a_command_acts_after_the_cpu_time_its_step_took(tmp_path):
    from emos.core.reconfig import ComponentServices

    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["sim", "driver"], timeout=60)
    odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=4096)
    moved_at = None
    start_x = None
    try:
        def first_motion():
            nonlocal moved_at, start_x
            for msg in odom.take():
                x, t = msg.pose.pose.position.x, msg.header.stamp.to_sec()
                if start_x is None:
                    start_x = x
                if moved_at is None and abs(x - start_x) > 1e-4:
                    moved_at = t
            return moved_at

        wait_until(first_motion, 120, what="the robot to move")
        status = ComponentServices("sim", system.ctx).execute_method("sim_status")
    finally:
        odom.close()
        assert system.stop() == 0
    first_command = float((tmp_path / "commanded.txt").read_text().split()[0])
    # Without the charge it would move within a physics tick of the command (both at 1.0 s).
    assert first_command == pytest.approx(1.0, abs=1e-6)
    assert moved_at >= first_command + 0.06 - 1e-6, (first_command, moved_at)
    assert moved_at <= first_command + 0.5, (first_command, moved_at)
    compute = status["compute"]
    assert compute["deadline_misses"] >= 1 and compute["compute_worst_s"] >= 0.06 and compute["bad_reports"] == 0
