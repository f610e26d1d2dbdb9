"""``emos bench ipc --peers``: the plumbing with the local peers (offline), iceoryx2 if its
benchmark environment exists, and the error for a registry that cannot be reached."""
import json
import os
import subprocess
import sys
import tempfile

import pytest

from emos.tools.bench import ipc_peers
from tests.bench_peers import unreachable_registry_env

pytestmark = pytest.mark.process

_TIMEOUT_S = 600  # bounds a hang only


def _bench(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from emos.tools.cli import main; sys.exit(main())", "bench", "ipc", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=_TIMEOUT_S, env=env)


def test_local_peers_are_measured_interleaved_with_a_row_per_transport_and_size():
    done = _bench("--peers", "shm-spin,pipe", "--rounds", "2", "--sizes", "8,65536", "--messages", "20", "--json")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert doc["mode"] == "peers" and doc["rounds"] == 2 and len(doc["loads"]) == 2
    rows = {(r["transport"], r["payload_bytes"]): r for r in doc["results"]}
    assert set(rows) == {(t, s) for t in ("emos", "shm-spin", "pipe") for s in (8, 65536)}
    for row in rows.values():
        assert [r["round"] for r in row["rounds"]] == [1, 2]
        for r in row["rounds"]:
            assert r["p50_us"] > 0 and r["p99_us"] >= r["p50_us"] and r["load"] >= 0 and r["samples"] >= 20
        p50s = [r["p50_us"] for r in row["rounds"]]
        assert row["p50_min_us"] == min(p50s) and row["p50_max_us"] == max(p50s)
        assert row["p50_spread"] == pytest.approx(max(p50s) / min(p50s), rel=0.01)
        assert "errors" not in row


def test_unknown_peers_and_bad_rounds_are_clear_usage_errors():
    done = _bench("--peers", "carrier-pigeon", "--sizes", "8")
    assert done.returncode == 2 and "unknown IPC peer 'carrier-pigeon'" in done.stderr
    assert "dora" in done.stderr and "zenoh" in done.stderr  # both measurable now (tests/ipc_peers/test_dora_zenoh_peers.py)
    done = _bench("--peers", "pipe", "--rounds", "0", "--sizes", "8")
    assert done.returncode == 2 and "--rounds" in done.stderr


def test_a_registry_that_cannot_be_reached_is_a_clear_error(tmp_path):
    env = unreachable_registry_env(tmp_path)
    done = _bench("--peers", "iceoryx2", "--sizes", "8", "--rounds", "1", env=env)
    assert done.returncode == 2
    assert "peer iceoryx2: cannot install iceoryx2==0.10.0" in done.stderr and "registry" in done.stderr
    assert "Traceback" not in done.stderr


needs_iceoryx2 = pytest.mark.skipif(
    not ipc_peers.peer_env_has("iceoryx2"),
    reason="the iceoryx2 peer environment (~/.cache/emos-bench/peers) is not installed; "
           "`emos bench ipc --peers iceoryx2` creates it from the package registry, which this test does not reach")
# The iceoryx2 tests compare iceoryx2's files before and after: run side by side on two workers,
# one saw the other's (a loaded suite run). One worker runs them, one after the other.
one_iceoryx2_at_a_time = pytest.mark.xdist_group("iceoryx2_peers")


def _iceoryx2_leftovers() -> set[str]:
    """What iceoryx2 runs left where they leave things: shared memory named iox2*, and the root
    directories the benchmark makes for them."""
    shm = {f"shm:{n}" for n in os.listdir(ipc_peers.IOX2_SHM_DIR) if n.startswith("iox2")}
    roots = {f"tmp:{n}" for n in os.listdir(tempfile.gettempdir()) if n.startswith("emos-bench-iox2-")}
    return shm | roots


@needs_iceoryx2
@one_iceoryx2_at_a_time
def test_iceoryx2_is_measured_from_its_own_environment_and_leaves_no_files():
    before = _iceoryx2_leftovers()
    done = _bench("--peers", "iceoryx2,iceoryx2-poll", "--rounds", "1", "--sizes", "64", "--messages", "20", "--json")
    assert done.returncode == 0, done.stderr
    rows = {r["transport"]: r for r in json.loads(done.stdout)["results"]}
    assert set(rows) == {"emos", "iceoryx2", "iceoryx2-poll"}
    assert rows["iceoryx2"]["p50_us"] > 0 and rows["iceoryx2-poll"]["p50_us"] > 0
    assert _iceoryx2_leftovers() - before == set()  # not even iceoryx2's 16 B node-management record


@needs_iceoryx2
@one_iceoryx2_at_a_time
def test_an_iceoryx2_peer_that_hangs_is_killed_with_its_echo_and_its_files_removed(monkeypatch):
    """A peer past its time limit: the peer and the echo it forked are killed (their process
    group), and what iceoryx2 made for them is removed all the same."""
    monkeypatch.setattr(ipc_peers, "_PEER_TIMEOUT_S", 8.0)
    tags = []
    real_prefix = ipc_peers.iceoryx2_file_prefix
    monkeypatch.setattr(ipc_peers, "iceoryx2_file_prefix", lambda tag: tags.append(tag) or real_prefix(tag))
    before = _iceoryx2_leftovers()
    with pytest.raises(RuntimeError, match="no result in 8 s"):
        ipc_peers.half_rtts_us("iceoryx2", 8, 10**9, 2)  # far more round trips than 8 s allow
    assert tags, "the peer was not started"
    assert _iceoryx2_leftovers() - before == set()
    alive = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if tags[0].encode() in f.read():
                    alive.append(pid)
        except OSError:
            continue
    assert alive == [], f"peer processes left running: {alive}"


@pytest.mark.unit
def test_only_the_files_of_the_tagged_iceoryx2_run_are_removed(tmp_path):
    ours, other = "0123456789abcdef", "fedcba9876543210"
    made = [ipc_peers.IOX2_SHM_DIR / f"{ipc_peers.iceoryx2_file_prefix(t)}node.global_mgmt" for t in (ours, other)]
    default = ipc_peers.IOX2_SHM_DIR / f"iox2_{ours}_test.global_mgmt"  # iceoryx2's own prefix: not ours to remove
    root = tmp_path / "root"
    (root / "nodes").mkdir(parents=True)
    (root / "nodes" / "x.node_monitor").write_bytes(b"")
    try:
        for path in (*made, default):
            path.write_bytes(b"\0" * 16)
        removed = ipc_peers.remove_iceoryx2_files(ours, root)
        assert removed == [made[0].name]
        assert not made[0].exists() and made[1].exists() and default.exists() and not root.exists()
    finally:
        for path in (*made, default):
            path.unlink(missing_ok=True)
