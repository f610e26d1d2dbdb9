"""``emos run --lockstep`` (emos.lockstep): the recipe's components become the Simulator's
lockstep consumers on simulated time; the recipe's own wiring is kept. The last test runs a
recipe that knows nothing of lockstep under ``emos run --lockstep``."""
from __future__ import annotations

import numpy as np
import pytest

from emos import lockstep
from emos.actors.nav.components import Controller, DriveManager
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.clock import ClockMode


@pytest.mark.unit
def test_every_component_but_the_simulator_and_the_monitor_becomes_a_consumer_on_sim_time():
    sim = Simulator("sim", config=SimulatorConfig(lockstep_consumers=["already_there"]))
    controller, driver, monitor = Controller(component_name="ctrl"), DriveManager(component_name="drv"), DriveManager(component_name="mon")
    names = lockstep.apply([controller, sim, driver, monitor], monitor=monitor)
    assert names == ["already_there", "ctrl", "drv"]
    assert sim.config.clock_mode is ClockMode.LOCKSTEP
    assert sim.config.lockstep_consumers == ["already_there", "ctrl", "drv"]
    assert controller.config.use_sim_time and driver.config.use_sim_time
    assert not monitor.config.use_sim_time and not sim.config.use_sim_time


@pytest.mark.unit
def test_a_recipe_without_one_simulator_is_refused_by_name():
    with pytest.raises(ValueError, match=r"0 Simulator component\(s\) \(none\)"):
        lockstep.apply([Controller(component_name="ctrl")])
    with pytest.raises(ValueError, match=r"2 Simulator component\(s\) \('a', 'b'\)"):
        lockstep.apply([Simulator("a"), Simulator("b")])


@pytest.mark.unit
def test_the_cli_switch_reaches_the_launcher_through_the_environment(monkeypatch):
    import argparse

    from emos.tools.cli import run

    parser = argparse.ArgumentParser()
    run.add_arguments(parser)
    assert parser.parse_args(["--lockstep", "r.py"]).lockstep and not parser.parse_args(["r.py"]).lockstep
    monkeypatch.delenv(lockstep.ENV_LOCKSTEP, raising=False)
    assert not lockstep.requested()
    monkeypatch.setenv(lockstep.ENV_LOCKSTEP, "1")
    assert lockstep.requested()


@pytest.mark.process
@pytest.mark.sim
def test_emos_run_lockstep_makes_the_recipes_components_answer_every_tick(tmp_path):
    """A recipe that knows nothing of lockstep: under ``--lockstep`` its Timed component answers
    every tick of the simulator's clock on ``/clock_ack/<name>``."""
    from emos.core.clock import ack_topic
    from emos.msgs import LockstepAck
    from emos.transport.pubsub import Subscriber
    from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

    recipe = '''
from emos.actors.sim import Simulator, SimulatorConfig

class Stepper(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

stepper = Stepper(component_name="stepper")
stepper.config.loop_rate = 10.0
launcher = Launcher()
launcher.add_pkg(components=[Simulator("sim", config=SimulatorConfig(world="house")), stepper])
launcher.bringup()
'''
    system = SystemUnderTest(tmp_path, recipe, env={"PYTHONPATH": str(REPO)}, args=["--lockstep"]).wait_up(components=["sim", "stepper"])
    try:
        assert "lockstep: the simulator waits every tick for stepper" in system.output(), system.output()[-3000:]
        acks = Subscriber(system.ctx, ack_topic("stepper"), LockstepAck, queue_size=1000)
        answered: list[float] = []

        def enough() -> bool:
            answered.extend(a.clock.to_sec() for a in acks.take())
            return len(answered) >= 20

        wait_until(enough, timeout=120, what="20 ticks answered by the recipe's component")
        acks.close()
        # one answer per tick of the 50 Hz clock, in order: the component is a lockstep consumer
        steps = np.diff(answered)
        assert np.all(steps > 0) and np.allclose(np.median(steps), 0.02), answered[:10]
    finally:
        assert system.stop() == 0, system.output()[-3000:]
