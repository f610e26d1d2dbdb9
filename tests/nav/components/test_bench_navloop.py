"""``emos bench navloop`` runs the three processes and matches commands to scans (short run)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.process


def test_navloop_json_shape_and_matched_commands():
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "navloop", "--duration", "3", "--warmup", "1.5", "--json"],
                         capture_output=True, text=True, timeout=150)
    assert out.returncode == 0, out.stderr[-3000:]
    data = json.loads(out.stdout)
    assert set(data) >= {"scan_to_cmd_ms", "missed_cycles", "cycles"}
    assert set(data["scan_to_cmd_ms"]) == {"p50", "p95"}
    assert data["cycles"] >= 40  # 3 s at 20 Hz, minus what a loaded machine delays
    assert 0 < data["scan_to_cmd_ms"]["p50"] <= data["scan_to_cmd_ms"]["p95"]
    assert data["missed_cycles"] < data["cycles"]  # commands came back for most scans


def test_navloop_rejects_an_unknown_algorithm():
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "navloop", "--algorithm", "MPC", "--json"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0 and "MPC" in out.stderr
