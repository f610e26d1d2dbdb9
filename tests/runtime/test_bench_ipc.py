"""``emos bench ipc`` end to end: both latency methods, the JSON contract, clean-up, bad input.

Timing is not asserted (shared, noisy machine); only that every measurement is real and sane.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid

import psutil
import pytest

from emos.supervisor.bench import ipc_pingpong
from emos.transport.context import SHM_DIR, runtime_root
from tests.runtime.helpers import REPO

SIZES = [8, 70000]
TRANSPORTS = {"emos", "mp_queue", "mp_pipe"}
ROW_KEYS = {"transport", "payload_bytes", "p50_us", "p99_us", "msgs_per_s", "dropped"}


def _bench(*extra: str, timeout: float = 120.0) -> tuple[subprocess.CompletedProcess, list[str]]:
    return _run_python(["-m", "emos", "bench", "ipc", *extra], timeout)


def _run_python(argv: list[str], timeout: float) -> tuple[subprocess.CompletedProcess, list[str]]:
    """Run Python in a subprocess (benchmarks fork: never from the test process, which may run
    threads); return its result and whatever it left behind (segments, run directory, helper
    processes). The helpers are found by an environment token they inherit."""
    token = uuid.uuid4().hex
    proc = subprocess.Popen(
        [sys.executable, *argv],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        env={**os.environ, "EMOS_BENCH_TEST_TOKEN": token},
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    # The bench owns the run it creates: ``emos.<its pid>-<start time>.`` (see emos.transport.context).
    run_prefix = f"{proc.pid}-"
    left = [n for n in os.listdir(SHM_DIR) if n.startswith(f"emos.{run_prefix}")]
    left += [str(d) for d in runtime_root().iterdir() if d.name.startswith(run_prefix)]
    for p in psutil.process_iter(["pid"]):
        try:
            if p.environ().get("EMOS_BENCH_TEST_TOKEN") == token and p.status() != psutil.STATUS_ZOMBIE:
                left.append(f"process {p.pid} {p.name()}")
        except psutil.Error:
            pass
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err), left


def _check_results(doc: dict, method: str) -> None:
    assert set(doc) == {"method", "cpus", "emos_depth", "emos_wake_spin_us", "results"}
    allowed = sorted(os.sched_getaffinity(0))
    assert doc["cpus"] in (allowed[:2], None)
    assert doc["method"] == method
    assert doc["emos_depth"] == 2 and doc["emos_wake_spin_us"] >= 0
    rows = doc["results"]
    assert {(r["transport"], r["payload_bytes"]) for r in rows} == {(t, s) for t in TRANSPORTS for s in SIZES}
    assert len(rows) == len(TRANSPORTS) * len(SIZES)
    for row in rows:
        assert set(row) == ROW_KEYS, row
        assert 0 < row["p50_us"] <= row["p99_us"], row
        assert row["msgs_per_s"] > 0, row
        assert row["dropped"] >= 0, row


@pytest.mark.parametrize("method", ["pingpong", "oneway"])
def test_bench_ipc_json_shape_and_no_leftovers(method: str) -> None:
    args = ["--json", "--sizes", ",".join(map(str, SIZES)), "--messages", "40", "--throughput-seconds", "0.2"]
    if method == "oneway":
        args += ["--method", "oneway", "--cpus", "none"]  # defaults (pingpong, pinned) are tested by the other case
    result, left = _bench(*args)
    assert result.returncode == 0, result.stderr
    # --json: the JSON document and nothing else on stdout (progress lines are for humans).
    _check_results(json.loads(result.stdout), method)
    assert left == []


def test_bench_ipc_human_table_names_the_method() -> None:
    result, left = _bench("--sizes", "8", "--messages", "40", "--throughput-seconds", "0.2", "--transports", "mp_pipe")
    assert result.returncode == 0, result.stderr
    assert "mp_pipe         8 B: latency (40 round trips)" in result.stdout
    assert "half a round trip" in result.stdout and "--method pingpong" in result.stdout
    assert left == []


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--method", "roundtrip"], "invalid choice: 'roundtrip'"),
        (["--depth", "1"], "--depth must be at least 2"),
        (["--cpus", "0"], "--cpus must be 'A,B'"),
        (["--cpus", "0,4096"], "may run on CPUs"),
        (["--transports", "emos,zmq"], "unknown transport(s) ['zmq']"),
        (["--sizes", "8,0"], "--sizes must be positive"),
        (["--sizes", "8,1k"], "--sizes must be comma-separated byte counts"),
    ],
)
def test_bench_ipc_bad_arguments_exit_2_with_a_clear_message(args: list[str], expected: str) -> None:
    result, left = _bench(*args, timeout=30.0)
    assert result.returncode == 2
    assert expected in result.stderr
    assert result.stdout == ""  # nothing was measured
    assert left == []


@pytest.mark.parametrize("transport", sorted(TRANSPORTS))
def test_pingpong_returns_exactly_the_requested_samples_after_warmup(transport: str) -> None:
    code = (
        "import json\n"
        "from emos.supervisor.bench import ipc_pingpong\n"
        f"print(json.dumps(ipc_pingpong.latency_us({transport!r}, 1024, 7)))\n"
    )
    result, left = _run_python(["-c", code], timeout=60.0)
    assert result.returncode == 0, result.stderr
    samples = json.loads(result.stdout)
    assert len(samples) == 7
    assert all(s > 0 for s in samples)
    assert left == []


def test_pingpong_echo_check_rejects_mangled_replies() -> None:
    import numpy as np

    payload = np.arange(16, dtype=np.uint8)
    ipc_pingpong._check_echo(payload.copy(), payload, first=True)
    with pytest.raises(RuntimeError, match="different bytes"):
        ipc_pingpong._check_echo(payload[::-1].copy(), payload, first=True)
    with pytest.raises(RuntimeError, match="returned 8 B for a 16 B payload"):
        ipc_pingpong._check_echo(payload[:8], payload, first=False)
