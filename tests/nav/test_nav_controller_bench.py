"""`emos bench nav` end to end (DWA step, kernels and the planning rows; small planning budget)."""
import json
import subprocess
import sys

import pytest

from emos.tools.bench import nav as bench

pytestmark = pytest.mark.process


def test_bench_nav_json_has_exactly_the_issue_keys():
    out = subprocess.run(
        [sys.executable, "-m", "emos", "bench", "nav", "--json", "--planners", "RRTConnect", "--planning-budget", "0.5"],
        capture_output=True, text=True, timeout=240, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout)
    assert set(result) == {"cost_eval_ms", "local_map_ms", "critical_zone_100k_ms", "critical_zone_scan_ms",
                           "dwa_step_ms", "mppi_step_ms", "swept_check_ms", "planning"}
    assert set(result["dwa_step_ms"]) == {"p50", "p95"}
    assert 0 < result["dwa_step_ms"]["p50"] <= result["dwa_step_ms"]["p95"]
    assert result["mppi_step_ms"]["cpu_p50"] > 0 and set(result["mppi_step_ms"]["stages_ms"]) >= {"rollout", "obstacles_critic"}
    for key in ("cost_eval_ms", "local_map_ms", "critical_zone_100k_ms", "critical_zone_scan_ms"):
        assert result[key] > 0
    assert [row["planner"] for row in result["planning"]] == ["RRTConnect"]
    assert result["planning"][0]["solved"] is True


def test_planning_errors_are_reported_not_faked():
    rows, error = bench._planning(0.1, ["NoSuchPlanner"])
    assert rows == []
    assert "NoSuchPlanner" in error
