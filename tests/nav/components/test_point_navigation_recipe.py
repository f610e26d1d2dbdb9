"""End to end: recipes/point_navigation.py drives the simulated robot to both goals."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.runtime.helpers import REPO

pytestmark = pytest.mark.process

RECIPE = REPO / "recipes" / "point_navigation.py"


def _run(tmp_path, timeout_s: str, limit: float):
    env = {**os.environ, "EMOS_NAV_OUT": str(tmp_path / "out"), "EMOS_NAV_TIMEOUT": timeout_s}
    return subprocess.run([sys.executable, str(RECIPE)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=limit)


def test_point_navigation_reaches_both_goals(tmp_path):
    proc = _run(tmp_path, "150", 240)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["success"] and summary["reached"] == [True, True] and not summary["collided"]
    assert summary["min_clearance_m"] > 0.0
    assert summary["path_length_m"] > 8.0  # round the table and armchair, not through them
    assert (tmp_path / "out" / "point_navigation.png").stat().st_size > 10_000
    assert "m left" in proc.stdout and "drive_manager=" in proc.stdout  # progress was printed
    assert "point navigation: SUCCESS" in proc.stdout


def test_point_navigation_exits_1_when_the_mission_times_out(tmp_path):
    proc = _run(tmp_path, "3", 120)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert not summary["success"] and summary["reached"][0] is False
    assert "point navigation: FAILURE" in proc.stdout
