"""``emos bench localize`` on the shipped Radish log, through the CLI as a user runs it: the
JSON has the documented keys and a tracking run on the first 80 scans of the real log stays
localized."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.localization.helpers import ACES_LOG

pytestmark = pytest.mark.process


def test_bench_localize_json_on_a_real_log():
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "localize", "--log", str(ACES_LOG),
                          "--seeds", "1", "--max-scans", "80", "--json"],
                         capture_output=True, text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["dataset"] == "aces-corrected" and result["mode"] == "tracking"
    row = result["results"][0]
    assert set(row) >= {"localizer", "position_rmse_m", "heading_rmse_deg", "converged_rate", "cpu_s_per_scan"}
    assert row["localizer"] == "emos" and row["scans"] == 80
    assert row["position_rmse_m"] < 0.1 and row["heading_rmse_deg"] < 2.0 and row["converged_rate"] == 1.0
    assert 0 < row["cpu_s_per_scan"] < 1.0


def test_bench_localize_refuses_a_missing_log_clearly(tmp_path):
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "localize", "--log", str(tmp_path / "nope.log.gz"), "--json"],
                         capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode != 0 and "nope.log.gz: cannot read it" in out.stderr
