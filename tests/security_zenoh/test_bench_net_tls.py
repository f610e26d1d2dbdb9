"""``emos bench net --tls``: both transports over mutual TLS with access control, alternating with
plain TCP in the same run, each TLS row with its overhead against the same transport over TCP."""
import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.process

pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")


def test_bench_net_tls_rows_and_overhead():
    proc = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "net", "--mode", "transport", "--tls", "--sizes", "8,70000",
                           "--messages", "10", "--rounds", "1", "--json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rows = {(r["transport"], r["payload_bytes"]): r for r in json.loads(proc.stdout)["results"]}
    for size in (8, 70000):
        for transport in ("emos-zenoh", "zenoh", "emos-zenoh+tls", "zenoh+tls"):
            row = rows[(transport, size)]
            assert row["samples"] >= 5 and row["lost"] == 0, row
        for transport in ("emos-zenoh", "zenoh"):
            tls, tcp = rows[(transport + "+tls", size)], rows[(transport, size)]
            assert tls["tls_overhead_p50_pct"] == round(100.0 * (tls["p50_us"] - tcp["p50_us"]) / tcp["p50_us"], 1)
