"""``emos bench hardware --json`` prints exactly the issue's keys, from the real pieces."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.process


def test_bench_hardware_json_has_exactly_the_keys_and_no_corrupt_scan():
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "hardware", "--json", "--commands", "30", "--scans", "5",
                          "--servo-seconds", "0.5"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert list(result) == ["cmd_to_wire_p50_ms", "cmd_to_wire_p99_ms", "scans_per_s", "corrupt_scans",
                            "parse_cpu_ratio_vs_pyrplidar", "servo_cycle_hz"]
    assert result["corrupt_scans"] == 0
    assert 0 < result["cmd_to_wire_p50_ms"] <= result["cmd_to_wire_p99_ms"]
    assert result["scans_per_s"] > 0 and result["servo_cycle_hz"] > 0 and result["parse_cpu_ratio_vs_pyrplidar"] > 0
