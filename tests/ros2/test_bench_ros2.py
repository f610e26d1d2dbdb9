"""``emos bench ros2 --json``: its JSON contract with tiny counts, and that it leaves nothing
behind (no process, no run directory, no EMOS or Fast DDS shared memory)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import psutil
import pytest

from emos.transport.context import SHM_DIR, runtime_root
from tests.ros2.conftest import fastdds_files, fastdds_names, free_domains
from tests.runtime.helpers import HANG_S, wait_until

pytestmark = pytest.mark.process


def _bench_processes() -> set[int]:
    """The benchmark's processes: its rclpy helpers, and the forks of `emos bench ros2` (the
    System, zygotes, workers carry its command line); not other tests' runs beside it."""
    found = set()
    for p in psutil.process_iter(["cmdline"]):
        try:
            cmd = " ".join(p.info["cmdline"] or [])
            if ("emos.tools.bench.ros2" in cmd or " bench ros2 " in cmd) and p.status() != psutil.STATUS_ZOMBIE:
                found.add(p.pid)
        except psutil.Error:
            pass
    return found


def test_bench_ros2_json_contract_and_nothing_left(tmp_path):
    (domain,) = free_domains(1)
    runs_before = set(os.listdir(runtime_root()))
    shm_before = {n for n in os.listdir(SHM_DIR) if n.startswith("emos.")}
    procs_before = _bench_processes()
    fastdds_before = fastdds_names()
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "ros2", "--json", "--sizes", "8,4096", "--messages", "5",
                          "--ros-domain-id", str(domain)], capture_output=True, text=True, timeout=6 * HANG_S, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    doc = json.loads(out.stdout)
    rows = doc["results"]
    assert [(r["pair"], r["payload_bytes"]) for r in rows] == [("rclpy-rclpy", 8), ("rclpy-rclpy", 4096), ("emos-rclpy", 8), ("emos-rclpy", 4096),
                                                                  ("emos-direct-rclpy", 8), ("emos-direct-rclpy", 4096)]
    for r in rows:
        assert r["p50_us"] > 0 and r["p99_us"] >= r["p50_us"], r
        assert r["cpu_us_per_msg_ros"] >= 0 and r["cpu_us_per_msg_initiator"] >= 0, r
        assert (r["cpu_us_per_msg_emos"] is None) == (r["pair"] == "rclpy-rclpy"), r
        assert r["round_trips"] >= 5 and r["seq_mismatches"] == 0, r
    # One progress line per pair on stderr.
    assert sum(line.startswith("  rclpy-rclpy:") for line in out.stderr.splitlines()) == 1, out.stderr
    assert sum(line.startswith("  emos-rclpy:") for line in out.stderr.splitlines()) == 1, out.stderr
    assert sum(line.startswith("  emos-direct-rclpy:") for line in out.stderr.splitlines()) == 1, out.stderr

    assert not psutil.Process().children(recursive=True)
    assert not (_bench_processes() - procs_before)
    # Other tests' runs and nodes may start and stop beside this one (pytest -n 2): what counts is
    # what no live process owns; a file of a node that is starting or stopping is gone (or in
    # use) a moment later, a leak stays.
    wait_until(lambda: not _leftovers(runs_before, shm_before, fastdds_before), timeout=10.0,
               what="nothing left by the benchmark: " + repr(_leftovers(runs_before, shm_before, fastdds_before)))


def _leftovers(runs_before: set[str], shm_before: set[str], fastdds_before: set[str]) -> list[str]:
    from tests.runtime.helpers import shm_in_use

    dead_runs = [d for d in set(os.listdir(runtime_root())) - runs_before if not psutil.pid_exists(int(d.split("-")[0]))]
    shm = {n for n in os.listdir(SHM_DIR) if n.startswith("emos.")} - shm_before - shm_in_use()
    return dead_runs + sorted(shm) + sorted(fastdds_files() - fastdds_before)


def test_bench_ros2_rejects_bad_options():
    for args, said in ((["--sizes", "4"], "at least 8 B"), (["--pairs", "rclpy-zenoh"], "--pairs"), (["--ros-domain-id", "500"], "domain id")):
        out = subprocess.run([sys.executable, "-m", "emos", "bench", "ros2", *args], capture_output=True, text=True, timeout=HANG_S)
        assert out.returncode == 2 and said in out.stderr, (args, out.stderr)
