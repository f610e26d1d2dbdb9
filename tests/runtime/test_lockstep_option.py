"""``emos run --lockstep`` (emos.lockstep): the recipe's components become the Simulator's
lockstep consumers on simulated time; the recipe's own wiring is kept. What it buys end to end
is shown by tests/nav/components/test_vision_tracking_recipes.py, which runs the spec's recipes
with it so that a busy machine cannot make the robot lose the person."""
from __future__ import annotations

import pytest

from emos import lockstep
from emos.actors.nav.components import Controller, DriveManager
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.clock import ClockMode

pytestmark = pytest.mark.unit


def test_every_component_but_the_simulator_and_the_monitor_becomes_a_consumer_on_sim_time():
    sim = Simulator("sim", config=SimulatorConfig(lockstep_consumers=["already_there"]))
    controller, driver, monitor = Controller(component_name="ctrl"), DriveManager(component_name="drv"), DriveManager(component_name="mon")
    names = lockstep.apply([controller, sim, driver, monitor], monitor=monitor)
    assert names == ["already_there", "ctrl", "drv"]
    assert sim.config.clock_mode is ClockMode.LOCKSTEP
    assert sim.config.lockstep_consumers == ["already_there", "ctrl", "drv"]
    assert controller.config.use_sim_time and driver.config.use_sim_time
    assert not monitor.config.use_sim_time and not sim.config.use_sim_time


def test_a_recipe_without_one_simulator_is_refused_by_name():
    with pytest.raises(ValueError, match=r"0 Simulator component\(s\) \(none\)"):
        lockstep.apply([Controller(component_name="ctrl")])
    with pytest.raises(ValueError, match=r"2 Simulator component\(s\) \('a', 'b'\)"):
        lockstep.apply([Simulator("a"), Simulator("b")])


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
