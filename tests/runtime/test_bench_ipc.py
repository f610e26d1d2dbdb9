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

from emos.tools.bench import ipc_pingpong
from emos.transport.context import SHM_DIR, runtime_root
from tests.runtime.helpers import REPO

pytestmark = pytest.mark.process

SIZES = [8, 70000]
TRANSPORTS = {"emos", "mp_queue", "mp_pipe"}
ROW_KEYS = {"transport", "payload_bytes", "p50_us", "p99_us", "msgs_per_s", "dropped", "seq_mismatches"}
COMPONENT_ROW_KEYS = {"transport", "payload_bytes", "p50_us", "p95_us", "p99_us", "round_trips", "seq_mismatches", "startup_resends"}


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


def _check_component(part: dict, messages: int) -> None:
    assert part["error"] is None and part["qos_depth"] == 10
    rows = part["results"]
    assert [r["payload_bytes"] for r in rows] == SIZES
    for row in rows:
        assert set(row) == COMPONENT_ROW_KEYS, row
        assert row["transport"] == "emos_component"
        assert 0 < row["p50_us"] <= row["p99_us"], row
        from emos.tools.bench.ipc import _samples_for

        assert row["round_trips"] == _samples_for(row["payload_bytes"], messages) and row["seq_mismatches"] == 0, row


def _check_results(doc: dict, method: str) -> None:
    assert set(doc) == {"mode", "method", "cpus", "emos_depth", "emos_wake_spin_us", "results", "component"}
    assert doc["mode"] == "both"
    _check_component(doc["component"], 40)
    allowed = sorted(os.sched_getaffinity(0))
    assert doc["cpus"] in (allowed[:2], None)
    assert doc["method"] == method
    assert doc["emos_depth"] == 2 and doc["emos_wake_spin_us"] >= 0
    rows = doc["results"]
    assert {(r["transport"], r["payload_bytes"]) for r in rows} == {(t, s) for t in TRANSPORTS for s in SIZES}
    assert len(rows) == len(TRANSPORTS) * len(SIZES)
    for row in rows:
        assert set(row) == ROW_KEYS, row
        assert row["seq_mismatches"] == 0, row
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
    result, left = _bench("--sizes", "8", "--messages", "40", "--throughput-seconds", "0.2", "--transports", "mp_pipe", "--mode", "transport")
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
        "from emos.tools.bench import ipc_pingpong\n"
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


def _dead_run_segments() -> set[str]:
    from emos.transport.context import run_is_alive

    return {n for n in os.listdir(SHM_DIR) if n.startswith("emos.") and not run_is_alive(n.split(".")[1])}


def test_bench_ipc_component_mode_goes_through_supervised_components_and_cleans_up() -> None:
    before = _dead_run_segments()
    result, left = _bench("--mode", "component", "--json", "--sizes", ",".join(map(str, SIZES)), "--messages", "30")
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert set(doc) == {"mode", "method", "cpus", "emos_depth", "emos_wake_spin_us", "component"}
    _check_component(doc["component"], 30)
    assert left == []
    assert _dead_run_segments() - before == set()  # the system's segments went with it


def test_bench_ipc_component_mode_human_table() -> None:
    result, left = _bench("--mode", "component", "--sizes", "8", "--messages", "20")
    assert result.returncode == 0, result.stderr
    assert "two supervised BaseComponents, default QoS (depth 10)" in result.stdout
    assert "emos_component" in result.stdout and "seq errors" in result.stdout
    assert left == []


def test_sequence_numbers_tell_a_stale_reply_from_the_expected_one() -> None:
    import numpy as np

    payload = np.zeros(32, np.uint8)
    ipc_pingpong._stamp(payload, 41)
    stale = payload.copy()
    ipc_pingpong._stamp(payload, 42)
    assert ipc_pingpong._seq_matches(payload.copy(), payload)
    assert not ipc_pingpong._seq_matches(stale, payload)
    tiny = np.zeros(3, np.uint8)  # payloads under 8 B carry the low bytes of the number
    ipc_pingpong._stamp(tiny, 0x010203)
    assert bytes(tiny) == bytes([3, 2, 1])


def test_a_sequence_mismatch_is_an_error_in_the_result(monkeypatch) -> None:
    from emos.tools.bench import ipc

    def mismatching(transport, size, count, depth=2):
        raise ipc_pingpong.SequenceMismatch(transport, size, 3)

    monkeypatch.setitem(ipc.METHODS, "pingpong", ("half a round trip", mismatching))
    monkeypatch.setattr(ipc.ipc_oneway, "throughput", lambda transport, size, seconds: (10, 1.0, 0))
    [row] = ipc.measure(["mp_pipe"], [64], 5, 0.1, progress=False)
    assert row["seq_mismatches"] == 3 and "3 repl(ies) carried the wrong sequence number" in row["error"]
