"""``emos bench net`` end to end: the transport mode (EMOS's Zenoh publisher and subscriber
against raw Zenoh) and the component mode (two real runs over Zenoh), the JSON contract, and that
nothing is left behind: no process, no shared memory (EMOS's or Zenoh's), no run directory, no
temporary file.

Timing is not asserted (shared, noisy machine); only that every measurement is real and sane."""
from __future__ import annotations

import json
import os
import shutil
import tempfile

import pytest

from emos.transport.context import SHM_DIR, run_is_alive, runtime_root
from tests.runtime.helpers import shm_in_use, wait_until
from tests.runtime.test_bench_ipc import _run_python

pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

pytestmark = pytest.mark.process

SIZES = [8, 70000]
MESSAGES = 30


def _leftovers_since(shm_before: set[str], runs_before: set[str]) -> list[str]:
    """Segments of runs that ended (a live run's are its own: other runs on this machine may be
    going on), Zenoh segments, and run directories that appeared since."""
    def leaked(name: str) -> bool:
        if name.endswith(".zenoh"):
            return True
        run_id = name.split(".")[1] if name.startswith("emos.") and name.count(".") >= 2 else ""
        return bool(run_id) and not run_is_alive(run_id)

    new = set(os.listdir(SHM_DIR)) - shm_before
    in_use = shm_in_use() if new else set()  # another test's live segments are not this one's leaks
    left = [n for n in new - in_use if leaked(n)]
    return left + sorted(set(d.name for d in runtime_root().iterdir()) - runs_before - {"zenoh-peers"})


def test_bench_net_both_modes_json_shape_and_no_leftovers(tmp_path, monkeypatch, request):
    from emos.tools.bench.net import _messages_for

    scratch = tmp_path / "tmp"  # the benchmark's temporary files (its Zenoh configurations) go here
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    # Its run directories, not other runs': a short path (sockets there must fit sun_path).
    runtime = tempfile.mkdtemp(prefix="ebn-")
    request.addfinalizer(lambda: shutil.rmtree(runtime, ignore_errors=True))
    monkeypatch.setenv("EMOS_RUNTIME_DIR", runtime)
    shm_before, runs_before = set(os.listdir(SHM_DIR)), set(d.name for d in runtime_root().iterdir())
    result, left = _run_python(["-m", "emos", "bench", "net", "--json", "--sizes", ",".join(map(str, SIZES)),
                                "--messages", str(MESSAGES), "--rounds", "2"], timeout=240)
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(doc) == {"method", "results", "component"}

    rows = doc["results"]
    assert sorted((r["transport"], r["payload_bytes"]) for r in rows) == sorted((t, s) for t in ("emos-zenoh", "zenoh") for s in SIZES)
    for row in rows:
        # "lost": no echo within the bench's 2 s (wall clock): on a loaded machine one comes later
        # (one of them beside a patrol run and three test workers); the bench fails past a quarter.
        assert 0 < row["p50_us"] <= row["p95_us"] and 0 <= row["lost"] <= MESSAGES // 4 and row["samples"] >= MESSAGES // 2, row
        assert ("overhead_p50_pct" in row) == (row["transport"] == "emos-zenoh"), row

    component = doc["component"]
    assert component["error"] is None, component
    assert [r["payload_bytes"] for r in component["results"]] == SIZES
    raw = {r["payload_bytes"]: r["p50_us"] for r in rows if r["transport"] == "zenoh"}
    for row in component["results"]:
        assert row["transport"] == "emos-zenoh-component" and row["seq_mismatches"] == 0, row
        assert row["round_trips"] == _messages_for(row["payload_bytes"], MESSAGES), row
        assert 0 < row["p50_us"] <= row["p95_us"] <= row["p99_us"], row
        expected = round(100.0 * (row["p50_us"] - raw[row["payload_bytes"]]) / raw[row["payload_bytes"]], 1)
        assert row["overhead_p50_pct"] == expected, row

    assert left == []
    # The benchmark's runs remove their segments as their processes end, which on a busy machine
    # may be just after the benchmark returned: a leak is what is still there after the hang bound.
    remaining: list[str] = []

    def cleaned() -> bool:
        remaining[:] = _leftovers_since(shm_before, runs_before)
        return not remaining

    try:
        wait_until(cleaned, what="the benchmark's segments and run directories removed")
    except AssertionError:
        raise AssertionError(f"left behind: {remaining}") from None
    assert sorted(p.name for p in scratch.iterdir()) == []


def test_bench_net_refuses_bad_sizes_naming_what_was_expected():
    result, left = _run_python(["-m", "emos", "bench", "net", "--sizes", "8,lots"], timeout=60)
    assert result.returncode == 2 and "--sizes" in result.stderr and "'8,lots'" in result.stderr
    assert left == []
    # The components carry an 8 B sequence number: a smaller payload is an error, not a bad sample.
    result, left = _run_python(["-m", "emos", "bench", "net", "--json", "--mode", "component", "--sizes", "4",
                                "--messages", "10", "--rounds", "1"], timeout=120)
    doc = json.loads(result.stdout.strip().splitlines()[-1])
    assert result.returncode == 1 and doc["component"]["results"] == [] and "at least 8 B" in doc["component"]["error"]
    assert left == []
