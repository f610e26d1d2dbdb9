"""``emos bench ipc --peers dora,zenoh`` (issue 34, item 3): dora-rs and zenoh shared memory
measured in the same run as the other peers, from the benchmark-only environment, and nothing
they start or make outlives a run: not on success, not on a hang, not on Ctrl-C. (An index that
cannot be reached is the same clear error as for iceoryx2: test_peers_cli.py.)

The tests that run dora or zenoh need the peer environment (``~/.cache/emos-bench/peers``) with
their packages; like the iceoryx2 tests they skip, with the reason, when it is not there (the
benchmark creates it from the package registry, which these tests do not reach)."""
import fcntl
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from emos.tools.bench import ipc_peers
from tests.runtime.helpers import ctrl_c_as_at_a_terminal

# One worker runs them all: each checks that no dora folder or zenoh segment is left that was not
# there before it began, which another of them running beside it would break.
pytestmark = [pytest.mark.process, pytest.mark.xdist_group("dora_zenoh_peers")]

_TIMEOUT_S = 600  # bounds a hang only


def _bench(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from emos.tools.cli import main; sys.exit(main())", "bench", "ipc", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=_TIMEOUT_S, env=env)


def _skip_unless(peer: str):
    return pytest.mark.skipif(
        not ipc_peers.peer_ready(peer),
        reason=f"the {peer} peer environment ({ipc_peers.peer_dir()}: {' '.join(ipc_peers.VENV_PEERS[peer][0])}) is not installed; "
               f"`emos bench ipc --peers {peer}` creates it from the package registry, which this test does not reach")


needs_zenoh = _skip_unless("zenoh")
needs_dora = _skip_unless("dora")


def _orphan_zenoh(before: set[str]) -> list[str]:
    """zenoh segments made since ``before`` that no live process holds (an exclusive flock
    succeeds only then: every process mapping a segment keeps a shared one)."""
    left = []
    for name in sorted(ipc_peers.zenoh_files() - before):
        try:
            fd = os.open(ipc_peers.PEER_SHM_DIR / name, os.O_RDONLY | os.O_NOFOLLOW)
        except FileNotFoundError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            left.append(name)
        except BlockingIOError:
            pass
        finally:
            os.close(fd)
    return left


def _temp_folders(prefix: str) -> set[str]:
    return {n for n in os.listdir(tempfile.gettempdir()) if n.startswith(prefix)}


def _processes_with(text: str) -> list[int]:
    """Live processes whose command line contains ``text`` (zombies have none)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if text.encode() in f.read():
                    found.append(int(pid))
        except OSError:
            continue
    return found


def _wait_for(predicate, what: str, timeout: float = 120.0):
    deadline = time.monotonic() + timeout  # bounds a hang only
    while time.monotonic() < deadline:
        got = predicate()
        if got:
            return got
        time.sleep(0.05)
    raise AssertionError(f"{what}: not seen in {timeout:.0f} s")


@needs_zenoh
@needs_dora
def test_dora_and_zenoh_are_measured_in_the_same_run_with_a_row_each_and_leave_nothing():
    before_shm, before_tmp = ipc_peers.zenoh_files(), _temp_folders("emos-bench-dora-")
    before_procs = set(_processes_with("ipc_peer_"))
    done = _bench("--peers", "dora,zenoh", "--rounds", "1", "--sizes", "65536", "--messages", "20", "--json")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert doc["mode"] == "peers" and len(doc["loads"]) == 1
    rows = {(r["transport"], r["payload_bytes"]): r for r in doc["results"]}
    assert set(rows) == {(t, 65536) for t in ("emos", "dora", "zenoh")}
    for (transport, _), row in rows.items():
        assert "errors" not in row, row
        [r] = row["rounds"]
        assert r["p50_us"] > 0 and r["p99_us"] >= r["p50_us"] and r["load"] >= 0 and r["samples"] >= 20
        assert row["about"] == ipc_peers.ABOUT[transport]
    assert rows[("zenoh", 65536)]["rounds"][0]["shm"] is True  # through zenoh's shared memory, as the row says
    assert "dora-rs==1.1.0" in rows[("dora", 65536)]["about"] and "ShmProvider" in rows[("zenoh", 65536)]["about"]
    assert _orphan_zenoh(before_shm) == []
    assert _temp_folders("emos-bench-dora-") - before_tmp == set()
    assert set(_processes_with("ipc_peer_")) - before_procs == set(), "peer processes left running"


@needs_zenoh
def test_a_zenoh_peer_that_hangs_is_killed_with_its_echo_and_its_shared_memory_removed(monkeypatch):
    monkeypatch.setattr(ipc_peers, "_PEER_TIMEOUT_S", 8.0)
    ports = []
    real_free_port = ipc_peers._free_port
    monkeypatch.setattr(ipc_peers, "_free_port", lambda: ports.append(real_free_port()) or ports[-1])
    before = ipc_peers.zenoh_files()
    with pytest.raises(RuntimeError, match="no result in 8 s"):
        ipc_peers.half_rtts_us("zenoh", 65536, 10**9, 2)
    assert ports, "the peer was not started"
    assert _processes_with(f"--port\0{ports[0]}\0") == [], "zenoh peer processes left running"
    assert _orphan_zenoh(before) == []


@needs_dora
def test_an_interrupted_dora_round_stops_everything_and_removes_its_files():
    """Ctrl-C (SIGINT) while a round runs dora: the benchmark unwinds (KeyboardInterrupt), and
    the launcher, ``dora run`` and the nodes go, with the run's folder and shared memory. (The
    peers run in a session of their own, so only the benchmark gets a terminal's Ctrl-C.)"""
    before = ipc_peers.zenoh_files()
    script = ("from emos.tools.bench import ipc_peers\n"
              "ipc_peers.run_rounds(['dora'], [65536], 1, 10**7, lambda size, wanted: wanted, 2)\n")
    bench = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=ctrl_c_as_at_a_terminal)
    try:
        # the ping node runs with its samples file in the run's folder: find that folder
        ping = _wait_for(lambda: _processes_with("--role\0ping\0--count\0" + str(10**7)), "the dora ping node")
        with open(f"/proc/{ping[0]}/cmdline", "rb") as f:
            args = f.read().split(b"\0")
        root = os.path.dirname(args[args.index(b"--out") + 1].decode())
        assert os.path.isdir(root)
        bench.send_signal(signal.SIGINT)
        out, err = bench.communicate(timeout=_TIMEOUT_S)
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.communicate()
    assert bench.returncode != 0 and "KeyboardInterrupt" in err, err
    assert not os.path.exists(root)
    assert _processes_with(root) == [], "dora processes left running"
    assert _orphan_zenoh(before) == []


def test_every_process_in_a_peer_session_is_killed_even_in_a_process_group_of_its_own():
    """What ``dora run`` does with its nodes: each in a process group of its own. Killing the
    peer's process group alone would leave them; the session catches them."""
    script = ("import os, subprocess, sys, time\n"
              "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'], process_group=0)\n"
              "print(child.pid, flush=True)\n"
              "time.sleep(600)\n")
    leader = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        child = int(leader.stdout.readline())
        assert os.getpgid(child) == child and os.getsid(child) == leader.pid
        ipc_peers._kill_group(leader.pid)
        leader.wait(timeout=60)

        def child_gone():
            try:
                with open(f"/proc/{child}/stat") as f:
                    return f.read().rsplit(")", 1)[1].split()[0] == "Z"  # dead, its parent not reaping it yet
            except FileNotFoundError:
                return True
        _wait_for(child_gone, "the child in its own process group to die", timeout=60)
    finally:
        if leader.poll() is None:
            leader.kill()
            leader.wait()
        leader.stdout.close()


def test_a_dora_command_that_does_not_run_here_is_named_with_the_reason(tmp_path, monkeypatch):
    (tmp_path / "bin").mkdir()
    fake = tmp_path / "bin" / "dora"
    fake.write_text("#!/bin/sh\necho 'GLIBC_2.99 not found' >&2\nexit 3\n")
    fake.chmod(0o755)
    monkeypatch.setenv(ipc_peers.ENV_PEER_DIR, str(tmp_path))
    problem = ipc_peers._command_problem("dora")
    assert problem is not None and f"{fake} --version exited 3" in problem and "GLIBC_2.99" in problem
    fake.unlink()
    assert f"the dora command is missing from {tmp_path / 'bin'}" == ipc_peers._command_problem("dora")
    assert ipc_peers._command_problem("zenoh") is None  # zenoh runs no command of its own
    assert not ipc_peers.peer_ready("dora")


@pytest.mark.unit
def test_only_new_zenoh_segments_that_no_process_holds_are_removed():
    """Real files in /dev/shm named as zenoh names its segments: the one made before the run,
    the one a live process holds (a shared flock, as zenoh keeps), and one not named as zenoh
    does stay; the new orphan goes."""
    base = 9_000_000_000_000 + os.getpid() * 10  # numbers far from zenoh's own picks
    old, held, orphan = (ipc_peers.PEER_SHM_DIR / f"{base + i}.zenoh" for i in range(3))
    other = ipc_peers.PEER_SHM_DIR / f"notanumber{base}.zenoh"
    paths = (old, held, orphan, other)
    fd = None
    try:
        old.write_bytes(b"\0" * 64)
        before = ipc_peers.zenoh_files()
        assert old.name in before and other.name not in before
        for path in (held, orphan, other):
            path.write_bytes(b"\0" * 64)
        fd = os.open(held, os.O_RDONLY)
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        assert ipc_peers.remove_zenoh_files(before) == [orphan.name]
        assert old.exists() and held.exists() and other.exists() and not orphan.exists()
    finally:
        if fd is not None:
            os.close(fd)
        for path in paths:
            path.unlink(missing_ok=True)


@pytest.mark.unit
def test_dora_and_zenoh_are_peers_with_a_description_for_every_row():
    assert ipc_peers.check_peers(["dora", "zenoh", "iceoryx2", "shm-spin", "pipe"]) is None
    assert set(ipc_peers.ABOUT) == {"emos", *ipc_peers.PEERS}
    assert set(ipc_peers.PEER_SCRIPTS) == set(ipc_peers.VENV_PEERS)
    for script in set(ipc_peers.PEER_SCRIPTS.values()):
        assert (ipc_peers.Path(ipc_peers.__file__).with_name(script)).exists()
    row = ipc_peers._summary("zenoh", 8, [{"round": 1, "load": 1.0, "p50_us": 10.0, "p99_us": 20.0, "samples": 40, "shm": False}])
    assert row["about"].startswith("zenoh (no shm)")
    row = ipc_peers._summary("zenoh", 8, [{"round": 1, "load": 1.0, "p50_us": 10.0, "p99_us": 20.0, "samples": 40, "shm": True}])
    assert row["about"] == ipc_peers.ABOUT["zenoh"]
