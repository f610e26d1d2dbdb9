"""`emos bench agents --json` prints exactly the keys the issue names (small sizes: this checks
the output contract, not performance)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.process, pytest.mark.statistical]


def test_bench_agents_json_contract():
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "agents", "--json",
                          "--entries", "300", "--queries", "20", "--repeats", "1", "--llm-queries", "5",
                          "--vision-seconds", "3", "--swaps", "1"],
                         capture_output=True, text=True, env=env, timeout=240, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert set(result) == {"route_ms", "route_accuracy", "chroma_query_ms", "router_split", "llm_overhead_ms",
                           "vision", "hotswap_ms"}
    assert set(result["llm_overhead_ms"]) == {"p50", "p95"} and set(result["hotswap_ms"]) == {"p50", "p95"}
    assert set(result["vision"]) == {"fps", "p95_ms", "dropped"} and result["vision"]["fps"] > 0
    assert 0 < result["hotswap_ms"]["p50"] < 30_000
    split = result["router_split"]
    assert sum(sum(row.values()) for row in split["confusion"].values()) == 37  # the odd half of 75 queries
    assert 0.0 <= split["test_accuracy"] <= 1.0
    assert set(result["route_ms"]) == {"p50", "p95"} and set(result["chroma_query_ms"]) == {"p50"}
    assert 0 < result["route_ms"]["p50"] <= result["route_ms"]["p95"]
    assert 0.9 <= result["route_accuracy"] <= 1.0
    assert result["chroma_query_ms"]["p50"] > 0
