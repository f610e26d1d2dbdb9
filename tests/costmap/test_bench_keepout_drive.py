"""``emos bench costmap --drive``: keepout zones kept while the stack drives the simulated house,
through the processes, with the Planner not told (``--scope local``): its plans cross the zones,
and only the Controller's and the DriveManager's keepout keep the robot out. Ground truth from the
Simulator is the referee."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from emos.tools.bench.costmap_drive import ENTRY_DEPTH, plan_missions

pytestmark = pytest.mark.process


def test_the_missions_put_a_zone_on_each_legs_route_with_a_way_round():
    goals, zones, dropped = plan_missions(6, seed=0, zone_side=0.6)
    assert len(goals) == 6 and len(zones) + dropped == 6 and len(zones) >= 4
    assert plan_missions(6, seed=0, zone_side=0.6)[0] == goals  # seeded


def test_a_planner_that_crosses_the_zones_does_not_take_the_robot_in(tmp_path):
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "costmap", "--drive", "2", "--scope", "local", "--seed", "0",
                          "--json"], capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout)
    assert {"scope", "legs", "zones", "entries", "deepest_m", "least_gap_m", "reached", "per_leg"} <= set(result)
    assert result["scope"] == "local" and result["legs"] == 2 and result["zones"] >= 1
    assert result["entries"] == 0 and result["deepest_m"] <= ENTRY_DEPTH, result["per_leg"]
    # The robot came to the zones (the check was put to the test), and the progress went to stderr.
    assert result["least_gap_m"] < 0.3, result["per_leg"]
    assert "leg 1/2" in out.stderr
