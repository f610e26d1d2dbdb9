"""The events-and-actions page's terrain-switching recipe
(recipes/concepts/quadruped_controller_recipe.py) run with ``emos run``: the first terrain seen
switches the gait once, with the terrain read from the topic; the same terrain again does not
(on_change), and a new one within the 60 s keep_event_delay does not either."""
from __future__ import annotations

import shutil
import time

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

PAGE = REPO / "recipes" / "concepts"
SWITCH = "New terrain detected! Switching gait."


def test_terrain_change_switches_the_gait_once_with_the_terrain_from_the_topic(tmp_path):
    shutil.copy(PAGE / "quadruped_controller.py", tmp_path / "quadruped_controller.py")  # the page's my_pkg
    system = SystemUnderTest(tmp_path, (PAGE / "quadruped_controller_recipe.py").read_text(), duration=120)
    probe = None
    try:
        system.wait_up(components=["quadruped_controller"], timeout=90)
        wait_until(lambda: "watching 1 events" in system.output(), 30, what="the monitor")
        probe = Probe(system)
        probe.pub("/terrain_type", M.String(data="stairs"))
        wait_until(lambda: "Gait controller: stairs" in system.output(), 30, what="the gait switch to stairs")
        probe.pub("/terrain_type", M.String(data="stairs"))  # unchanged: on_change keeps it quiet
        probe.pub("/terrain_type", M.String(data="sand"))  # changed, but within keep_event_delay=60 s
        time.sleep(2.0)  # a wrong second switch would show within this
        out = system.output()
        assert out.count(SWITCH) == 1 and "Gait controller: sand" not in out, out[-3000:]
    finally:
        if probe is not None:
            probe.close()
        assert system.stop() == 0, system.output()[-3000:]
