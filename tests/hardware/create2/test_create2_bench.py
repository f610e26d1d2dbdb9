"""``/cmd_vel`` -> Drive Direct bytes through a real component process (``emos run``)."""
from __future__ import annotations

import pytest

from emos.actors.hardware.create2.bench import bench_cmd_to_wire

pytestmark = pytest.mark.process


def test_cmd_to_wire_bench_through_a_component_process():
    result = bench_cmd_to_wire(commands=40, rate=50.0)
    # Every command reached the wire, each matched by its own wheel speed; the numbers are
    # measurements (reported by emos bench), not budgets, so only their sanity is asserted.
    assert result["commands"] == 40
    assert 0 < result["cmd_to_wire_p50_ms"] <= result["cmd_to_wire_p99_ms"] <= result["cmd_to_wire_max_ms"]
