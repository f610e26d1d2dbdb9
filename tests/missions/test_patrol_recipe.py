"""The patrol recipe (WaypointFollower + the navigation stack + the Simulator, real processes):
an unreachable waypoint (inside the sofa) is reported with the reason and the mission goes on or
stops as stop_on_failure says; the reachable rooms get their picture."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.runtime.helpers import kill_leftover_systems

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]

RECIPE = Path(__file__).resolve().parents[2] / "recipes" / "patrol.py"


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


def _run(tmp_path: Path, stop_on_failure: bool) -> tuple[int, dict, str]:
    env = {**os.environ, "EMOS_PATROL_OUT": str(tmp_path / "out"), "EMOS_PATROL_ROOMS": json.dumps([[2.5, 2.0], [8.0, 1.0]]),
           "EMOS_PATROL_STOP_ON_FAILURE": "1" if stop_on_failure else "0", "EMOS_PATROL_TIMEOUT": "900"}
    proc = subprocess.run([sys.executable, "-m", "emos", "run", str(RECIPE)], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=1200)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    return proc.returncode, summary, proc.stdout + proc.stderr


@pytest.mark.parametrize("stop_on_failure", [False, True])
def test_unreachable_waypoint_follows_the_policy(tmp_path, stop_on_failure):
    rc, summary, output = _run(tmp_path, stop_on_failure)
    assert rc == 1, output[-3000:]  # a missed waypoint is not a success
    assert len(summary["missed_waypoints"]) == 1, summary
    missed = summary["missed_waypoints"][0]
    assert missed.startswith("1: unreachable: the planner says"), missed
    assert summary["pictures"] == ["waypoint_0_0.png"]  # the reachable room got its picture
    assert summary["collisions"] == 0
    if stop_on_failure:
        assert "stopped (stop_on_failure)" in summary["message"] and summary["laps"] == 0
    else:
        assert summary["laps"] == 1  # it went on to the last waypoint (home) and finished the lap
