"""``emos bench ipc --peers ...``: EMOS topics against the IPC a robotics engineer would pick
instead, measured in the same run by the same method, interleaved over ``--rounds``.

Method, for every transport: half a round trip (``ipc_pingpong``), a numpy payload stamped with
a sequence number that the reply must carry back, both ends pinned to their CPUs (``--cpus``),
the same sizes and warm-up. Each round measures every (size, transport) once, in an order that
rotates from round to round, and records the machine's load average when it starts; the result
is one row per transport and size with p50 and p99 per round and their spread (max / min over
rounds), because on a shared machine a number that swings between rounds is a finding.

Peers:

* ``pipe``: ``multiprocessing.Pipe`` (``ipc_pingpong``'s), bytes turned into numpy at the end.
* ``shm-spin``: raw shared memory and a spinning reader: a sequence word per direction and one
  ``np.copyto`` per hop, nothing else; the floor any shared-memory transport pays for the copies.
* ``iceoryx2`` / ``iceoryx2-poll``: iceoryx2 0.10 with loaned samples, the receiver blocking in an
  event service's ``Listener.blocking_wait`` / spinning on ``receive`` (``ipc_peer_iceoryx2.py``).
* ``zenoh``: eclipse-zenoh's Python API with its shared-memory provider (``ShmProvider.alloc``,
  ``put`` of the ``ZShmMut``), two peer sessions over ``tcp/127.0.0.1`` with no router and no
  scouting (``ipc_peer_zenoh.py``).
* ``dora``: dora-rs Python nodes ``ping`` and ``pong`` in a dataflow started with ``dora run``
  (``ipc_peer_dora.py``).

Each row says what its transport is (``about``), and a round of a peer that reports how the
payload travelled (zenoh: ``shm``) records it.

Peers that need packages run in the benchmark-only virtual environment of ``peer_env`` (pinned
versions under ``$EMOS_BENCH_PEERS``, never a dependency of EMOS). Every peer script runs in a session of its own; when it ends, however it
ends, every process left in that session is killed and the files the peer made are removed
(``remove_iceoryx2_files``, ``remove_zenoh_files``, the run's temporary folder).
"""
from __future__ import annotations

import fcntl
import json
import mmap
import os
import shutil
import signal
import stat
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np

from emos.tools.bench import ipc_common, ipc_pingpong, peer_env
from emos.tools.bench.common import percentiles
from emos.tools.bench.peer_env import ENV_PEER_DIR as ENV_PEER_DIR
from emos.tools.bench.peer_env import PeerUnavailable as PeerUnavailable
from emos.tools.bench.peer_env import peer_dir as peer_dir
from emos.tools.bench.peer_env import peer_env_has as peer_env_has
from emos.tools.bench.peer_env import peer_python as peer_python
from emos.transport.fence import WEAK_ORDERING

LOCAL_PEERS = ["shm-spin", "pipe"]
ICEORYX2 = "iceoryx2==0.10.0"
ZENOH = "eclipse-zenoh==1.10.2"  # the version EMOS's own `net` extra requires at least
DORA = ["dora-rs==1.1.0", "dora-rs-cli==1.1.0"]  # the node API, and the `dora` command
# Peer name -> (packages for the peer environment, the module that checks they import).
VENV_PEERS: dict[str, tuple[list[str], str]] = {
    "iceoryx2": ([ICEORYX2, "numpy"], "iceoryx2"),
    "iceoryx2-poll": ([ICEORYX2, "numpy"], "iceoryx2"),
    "zenoh": ([ZENOH, "numpy"], "zenoh"),
    "dora": ([*DORA, "pyarrow", "numpy"], "dora"),
}
# Commands a peer runs from the environment's bin/, with the arguments that prove they run here.
PEER_COMMANDS: dict[str, list[str]] = {"dora": ["dora", "--version"]}
PEER_SCRIPTS = {"iceoryx2": "ipc_peer_iceoryx2.py", "iceoryx2-poll": "ipc_peer_iceoryx2.py",
                "zenoh": "ipc_peer_zenoh.py", "dora": "ipc_peer_dora.py"}
PEERS = LOCAL_PEERS + list(VENV_PEERS)
# What each row measures (the JSON's ``about``): the transport, the version, how it is driven.
ABOUT = {
    "emos": "EMOS topic rings under a bare event loop (as --mode transport)",
    "pipe": "multiprocessing.Pipe; bytes, np.frombuffer at the receiver",
    "shm-spin": "raw shared memory, a spinning reader, one np.copyto per hop: the copies alone",
    "iceoryx2": f"{ICEORYX2}: loaned samples, event service, Listener.blocking_wait",
    "iceoryx2-poll": f"{ICEORYX2}: loaned samples, the receiver spinning on receive",
    "zenoh": f"{ZENOH} Python: ShmProvider.alloc + put of a ZShmMut (POSIX shared memory), two peer sessions "
             "over tcp/127.0.0.1, no router, no scouting; the receiver copies out with to_bytes()",
    "dora": f"{' + '.join(DORA)}: two Python nodes under `dora run` (daemon in that process), Arrow arrays through "
            "send_output (zenoh shared memory between nodes, pool 5x the payload), the reply read with to_numpy(zero_copy_only=True)",
}
ABOUT_NO_SHM = {"zenoh": f"zenoh (no shm): {ZENOH} Python, plain put of bytes over tcp/127.0.0.1 (the payload did not travel "
                         "through shared memory), no router, no scouting"}
_PEER_TIMEOUT_S = 600.0  # one peer measurement; only a hung peer reaches it
_KILL_WAIT_S = 60.0  # a SIGKILLed process that has not exited by then is stuck in the kernel
# Where iceoryx2 and zenoh keep their shared memory on Linux, and how iceoryx2's files of our runs start.
PEER_SHM_DIR = Path("/dev/shm")
IOX2_SHM_DIR = PEER_SHM_DIR
_IOX2_PREFIX = "iox2emos"
ZENOH_SHM_SUFFIX = ".zenoh"  # zenoh's shared memory: /dev/shm/<number>.zenoh
_REPORTED = ("shm",)  # zenoh: whether the reply arrived as shared memory


def _command_problem(peer: str) -> str | None:
    """Why the command ``peer`` runs from the environment's bin/ does not run here, or None."""
    if peer not in PEER_COMMANDS:
        return None
    name, *args = PEER_COMMANDS[peer]
    path = peer_dir() / "bin" / name
    if not path.exists():
        return f"the {name} command is missing from {path.parent}"
    try:
        ran = subprocess.run([str(path), *args], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{path} {' '.join(args)} does not run here: {exc}"
    if ran.returncode != 0:
        return f"{path} {' '.join(args)} exited {ran.returncode}: {(ran.stderr or ran.stdout).strip()[-300:]}"
    return None


def peer_ready(peer: str) -> bool:
    """Whether ``peer``'s packages (and commands) are in the peer environment (no install attempted)."""
    return peer_env_has(VENV_PEERS[peer][1]) and _command_problem(peer) is None


def ensure_peer_env(peer: str, log: Any = None) -> Path:
    """The peer environment's Python with ``peer``'s packages, creating and filling it if needed."""
    packages, module = VENV_PEERS[peer]
    return peer_env.ensure(peer, packages, module, log=log, command_problem=lambda: _command_problem(peer))


# ------------------------------------------------------------------ shm-spin: the copies alone
_SEQ_PING, _SEQ_PONG = 0, 1  # u64 words at the start of the shared page
_STOP = (1 << 64) - 1


def _shm_echo(mm: mmap.mmap, size: int) -> None:
    q = memoryview(mm).cast("Q")
    ping = np.frombuffer(mm, np.uint8, size, 64)
    pong = np.frombuffer(mm, np.uint8, size, 64 + _stride(size))
    last = 0
    while True:
        while q[_SEQ_PING] == last:
            os.sched_yield()
        last = q[_SEQ_PING]
        if last == _STOP:
            return
        np.copyto(pong, ping)
        q[_SEQ_PONG] = last  # x86-64 keeps the copy's stores before this one (total store order)


def _stride(size: int) -> int:
    return (size + 63) // 64 * 64


def _shm_spin_half_rtts(size: int, count: int) -> list[float]:
    if WEAK_ORDERING:
        raise PeerUnavailable("peer shm-spin: needs a CPU with total store order (x86-64); this one reorders stores")
    mm = mmap.mmap(-1, 64 + 2 * _stride(size))  # anonymous and shared: the forked echo sees it
    q = memoryview(mm).cast("Q")
    ping = np.frombuffer(mm, np.uint8, size, 64)
    pong = np.frombuffer(mm, np.uint8, size, 64 + _stride(size))
    payload = ipc_common.random_payload(size)
    total = ipc_pingpong.warmup_round_trips(count) + count
    proc = ipc_common.start_child(_shm_echo, (mm, size), "emos:bench-echo")
    rtts: list[int] = []
    try:
        for i in range(1, total + 1):
            ipc_pingpong._stamp(payload, i)
            start = time.perf_counter_ns()
            np.copyto(ping, payload)
            q[_SEQ_PING] = i
            deadline = time.monotonic() + 30.0
            while q[_SEQ_PONG] != i:
                os.sched_yield()
                if not proc.is_alive() or time.monotonic() > deadline:
                    raise RuntimeError(f"shm-spin echo gave no reply (exit code {proc.exitcode})")
            reply = pong  # the reply is usable as a numpy array as it is
            rtts.append(time.perf_counter_ns() - start)
            if not ipc_pingpong._seq_matches(reply, payload):
                raise RuntimeError(f"shm-spin at {size} B: reply {i} carried the wrong sequence number")
            ipc_pingpong._check_echo(reply, payload, first=i == 1)
        q[_SEQ_PING] = _STOP
    finally:
        if q[_SEQ_PING] != _STOP:
            q[_SEQ_PING] = _STOP
        ipc_common.stop_child(proc)
        q.release()  # the mapping itself goes with the last array viewing it
    return [ns / 2e3 for ns in rtts[total - count :]]


# ------------------------------------------------------------------ peers in their own environment
def iceoryx2_file_prefix(tag: str) -> str:
    """The start of the name of every file an iceoryx2 peer run tagged ``tag`` makes (its
    services are ``emos-bench/<tag>/...``; see ``ipc_peer_iceoryx2.py``, "Files")."""
    return f"{_IOX2_PREFIX}{tag}_"


def remove_iceoryx2_files(tag: str, root: Path) -> list[str]:
    """Remove what an iceoryx2 peer run tagged ``tag`` left: its shared memory (``/dev/shm``
    files named by its prefix: only regular files of ours) and its root directory ``root``
    (made for that run alone). Returns the names removed from ``/dev/shm``."""
    prefix = iceoryx2_file_prefix(tag)
    removed = []
    try:
        names = os.listdir(IOX2_SHM_DIR)
    except OSError:
        names = []
    for name in names:
        if not name.startswith(prefix):
            continue
        path = IOX2_SHM_DIR / name
        try:
            st = os.lstat(path)
            if stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid():
                os.unlink(path)
                removed.append(name)
        except FileNotFoundError:
            pass
    shutil.rmtree(root, ignore_errors=True)
    return removed


def zenoh_files() -> set[str]:
    """The zenoh shared-memory segments in ``/dev/shm`` now (``<number>.zenoh``)."""
    try:
        names = os.listdir(PEER_SHM_DIR)
    except OSError:
        return set()
    return {n for n in names if n.endswith(ZENOH_SHM_SUFFIX) and n[: -len(ZENOH_SHM_SUFFIX)].isdigit()}


def remove_zenoh_files(before: set[str]) -> list[str]:
    """Remove the zenoh segments that appeared since ``before`` (taken when a peer run started)
    and that no live process holds: every process that maps a segment keeps a shared ``flock``
    on it, so an exclusive one succeeds only on a segment left behind, which is how zenoh's own
    orphan clean-up tells them apart. Only regular files of our uid. Returns the names removed."""
    removed = []
    for name in sorted(zenoh_files() - before):
        path = PEER_SHM_DIR / name
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except OSError:
            continue  # gone meanwhile, or not ours to open
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid():
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue  # a live zenoh process (not necessarily ours) maps it
            os.unlink(path)
            removed.append(name)
        except FileNotFoundError:
            pass
        finally:
            os.close(fd)
    return removed


def _run_peer_group(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run a peer script in a session (and process group) of its own; when it ends, however it
    ends (a timeout, Ctrl-C, an error), every process still in that session goes: the echo it
    forked, a ``dora run`` and the nodes it started in process groups of their own."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(cwd), start_new_session=True)
    try:
        out, err = proc.communicate(timeout=_PEER_TIMEOUT_S)
    except BaseException:
        _kill_group(proc.pid)
        proc.communicate()
        raise
    _kill_group(proc.pid)  # a peer that exited by itself has normally left nothing: then a no-op
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def _has_exited(pid: int) -> bool:
    """Every thread of ``pid`` has exited (or the process is gone): only then are its files closed
    and its locks released. A multi-threaded process's leader shows Z while its other threads are
    still tearing down, holding the files they share."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return True
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/stat", "rb") as f:
                if f.read().rsplit(b")", 1)[1].split()[0] != b"Z":
                    return False
        except (OSError, IndexError):
            continue  # that thread is gone
    return True


def _session_members(sid: int, *, living: bool = False) -> list[int]:
    """The processes whose session is ``sid`` (``/proc/<pid>/stat``, field 6); with ``living``,
    not those that have exited and wait to be reaped (see ``_has_exited``)."""
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
        except (OSError, IndexError):
            continue  # gone meanwhile
        if len(fields) > 3 and int(fields[3]) == sid and not (living and _has_exited(int(entry))):
            pids.append(int(entry))
    return pids


def _kill_group(pgid: int) -> None:
    """SIGKILL the process group a peer script leads (made by ``start_new_session``) and every
    process left in its session. The session id stays reserved while any member lives, so no
    unrelated process can carry it.

    Returns once they have all exited: SIGKILL is only delivered, and a node that still maps a
    zenoh segment still holds its lock, so ``remove_zenoh_files`` right after would leave that
    segment behind. (The wait is bounded; a process that outlives it is reported.)"""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    deadline = time.monotonic() + _KILL_WAIT_S
    while True:
        members = _session_members(pgid, living=True)
        if not members:
            return
        for pid in members:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if time.monotonic() > deadline:
            print(f"emos bench ipc: processes {members} of a peer's session outlived SIGKILL for {_KILL_WAIT_S:.0f} s",
                  file=sys.stderr)
            return
        time.sleep(0.01)


def _free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (the kernel's pick for port 0)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _venv_peer(peer: str, size: int, count: int) -> dict[str, Any]:
    """Run ``peer``'s script with the peer environment's Python; its JSON result (``half_rtt_us``
    and what else it reports). Its files are removed on every path (see the module doc)."""
    python = ensure_peer_env(peer)
    script = Path(__file__).with_name(PEER_SCRIPTS[peer])
    cpus = "none" if ipc_common.PLACEMENT is None else f"{ipc_common.PLACEMENT[0]},{ipc_common.PLACEMENT[1]}"
    tag = uuid.uuid4().hex[:16]
    cmd = [str(python), str(script), "--size", str(size), "--count", str(count),
           "--warmup", str(ipc_pingpong.warmup_round_trips(count)), "--cpus", cpus]
    zenoh_before = zenoh_files()
    root: Path | None = None
    if peer.startswith("iceoryx2"):
        root = Path(tempfile.mkdtemp(prefix=f"emos-bench-iox2-{tag}-"))
        cmd += ["--wait", "poll" if peer.endswith("-poll") else "event", "--tag", tag,
                "--prefix", iceoryx2_file_prefix(tag), "--root", str(root)]
    elif peer == "zenoh":
        cmd += ["--tag", tag, "--port", str(_free_port())]
    elif peer == "dora":
        root = Path(tempfile.mkdtemp(prefix=f"emos-bench-dora-{tag}-"))
        cmd += ["--root", str(root)]
    try:
        done = _run_peer_group(cmd, peer_dir())
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"peer {peer} at {size} B: no result in {_PEER_TIMEOUT_S:.0f} s") from None
    finally:  # the peer and everything it started have been reaped or killed on every path
        if peer.startswith("iceoryx2") and root is not None:
            remove_iceoryx2_files(tag, root)
        elif root is not None:
            shutil.rmtree(root, ignore_errors=True)
        remove_zenoh_files(zenoh_before)  # dora 1.1 moves outputs through zenoh shared memory too
    if done.returncode != 0:
        raise RuntimeError(f"peer {peer} at {size} B failed (exit {done.returncode}): {done.stderr.strip()[-400:]}")
    try:
        doc = json.loads(done.stdout)
        samples = [float(v) for v in doc["half_rtt_us"]]
    except (ValueError, KeyError, TypeError):
        raise RuntimeError(f"peer {peer} at {size} B printed no result: {done.stdout[-200:]!r}") from None
    # What else a peer may report, each a flag (its output is not trusted to shape the rows).
    reported = {k: doc[k] for k in _REPORTED if isinstance(doc.get(k), bool)}
    return {"half_rtt_us": samples, **reported}


def _measure(transport: str, size: int, count: int, depth: int) -> tuple[list[float], dict[str, Any]]:
    """``count`` half round trips of ``transport``, and what the peer reported about the run."""
    if transport == "emos":
        return ipc_pingpong.latency_us("emos", size, count, depth=depth), {}
    if transport == "pipe":
        return ipc_pingpong.latency_us("mp_pipe", size, count), {}
    if transport == "shm-spin":
        return _shm_spin_half_rtts(size, count), {}
    if transport in VENV_PEERS:
        doc = _venv_peer(transport, size, count)
        return doc.pop("half_rtt_us"), doc
    raise PeerUnavailable(f"unknown IPC peer {transport!r}; choose from {', '.join(PEERS)}")


def half_rtts_us(transport: str, size: int, count: int, depth: int) -> list[float]:
    """``count`` half round trips of ``transport`` (``emos`` or a peer), after a warm-up."""
    return _measure(transport, size, count, depth)[0]


def check_peers(names: list[str]) -> str | None:
    """An error message for peers this version cannot measure, or None."""
    for name in names:
        if name not in PEERS:
            return f"unknown IPC peer {name!r}; choose from {', '.join(PEERS)}"
    return None


def prepare(names: list[str], log: Any = None) -> None:
    """Install what the peers need before the first round, so no round pays for it."""
    for name in names:
        if name in VENV_PEERS:
            ensure_peer_env(name, log)


def load_average() -> float:
    return round(os.getloadavg()[0], 2)


def run_rounds(transports: list[str], sizes: list[int], rounds: int, messages: int, samples_for: Any,
               depth: int, progress: Any = None) -> dict[str, Any]:
    """Every (transport, size) once per round, in a rotating order; see the module doc."""
    per: dict[tuple[str, int], list[dict[str, Any]]] = {(t, s): [] for s in sizes for t in transports}
    loads: list[float] = []
    for r in range(rounds):
        load = load_average()
        loads.append(load)
        if progress:
            progress(f"round {r + 1}/{rounds} (load average {load:.2f})")
        for size in sizes:
            shift = r % len(transports)
            for transport in transports[shift:] + transports[:shift]:
                count = samples_for(size, messages)
                entry: dict[str, Any] = {"round": r + 1, "load": load_average()}
                try:
                    with ipc_common.placed():
                        samples, reported = _measure(transport, size, count, depth)
                    p = percentiles(samples)
                    entry.update(p50_us=round(p["p50"], 2), p99_us=round(p["p99"], 2), samples=count, **reported)
                except (RuntimeError, OSError, ipc_pingpong.SequenceMismatch) as exc:
                    entry["error"] = str(exc)
                per[(transport, size)].append(entry)
                if progress:
                    got = f"p50 {entry['p50_us']:.1f} us, p99 {entry['p99_us']:.1f} us" if "error" not in entry else f"ERROR {entry['error']}"
                    progress(f"  {transport:>13} {size:>9,} B: {got}")
    rows = [_summary(t, s, per[(t, s)]) for s in sizes for t in transports]
    return {"rounds": rounds, "loads": loads, "results": rows}


def _spread(values: list[float]) -> float | None:
    return round(max(values) / min(values), 2) if values and min(values) > 0 else None


def _summary(transport: str, size: int, rounds: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rounds if "error" not in r]
    p50s, p99s = [r["p50_us"] for r in ok], [r["p99_us"] for r in ok]
    no_shm = any(r.get("shm") is False for r in ok)
    row: dict[str, Any] = {
        "transport": transport, "payload_bytes": size,
        "about": ABOUT_NO_SHM[transport] if no_shm and transport in ABOUT_NO_SHM else ABOUT.get(transport, transport),
        "rounds": rounds,
        "p50_us": round(statistics.median(p50s), 2) if p50s else None,
        "p99_us": round(statistics.median(p99s), 2) if p99s else None,
        "p50_min_us": min(p50s, default=None), "p50_max_us": max(p50s, default=None),
        "p50_spread": _spread(p50s), "p99_spread": _spread(p99s),
    }
    errors = [r["error"] for r in rounds if "error" in r]
    if errors:
        row["errors"] = errors
    return row
