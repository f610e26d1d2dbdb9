"""zenoh ping-pong for ``emos bench ipc --peers zenoh``: run by the peer environment's Python
(``ipc_peers.py`` installs eclipse-zenoh there; never imported by EMOS, never a dependency of it).

The same method as the EMOS ping-pong (``ipc_pingpong.py``) and the iceoryx2 peer: the initiator
stamps a numpy payload and publishes it, the echo publishes the same bytes back, the initiator
stops the clock once the reply is a numpy array, and a sample is half that round trip. Both
processes are pinned to their CPUs before zenoh starts, so zenoh's own threads run there too.

How a zenoh user sends a frame through shared memory with the Python API (eclipse-zenoh 1.x):
a ``zenoh.shm.ShmProvider`` (POSIX backend) per process, ``provider.alloc(n)`` for a
``ZShmMut`` buffer, the bytes written into it (``buf[:] = ...``: the API takes only ``bytes``
or ``bytearray``, so the payload is a numpy array over a ``bytearray`` and one copy fills the
buffer), then ``publisher.put(buf)``. The receiver gets a ``ZBytes`` that refers to the
sender's shared memory (``payload.as_shm()`` is not None), but the Python API has no view of
it: ``to_bytes()`` copies it out, and that copy is part of every hop. Versions whose Python API
has no ``zenoh.shm`` put ``bytes`` instead; the result says which (``"shm"``).

Sessions: two peers on localhost with no router: multicast and gossip scouting off, the echo
listening on ``tcp/127.0.0.1:PORT`` (a free port the benchmark found) and the initiator
connecting to it; shared memory enabled in the transport. Publishers block on congestion and are
express (no batching), as zenoh's own ping example does.

Files. zenoh's shared memory is ``/dev/shm/<number>.zenoh``, flock-ed (shared) by every process
that maps it; one segment per process can outlive it. The benchmark
(``ipc_peers.remove_zenoh_files``) removes, after the run, the new segments no live process
holds. Prints ``{"half_rtt_us": [...], "shm": bool}``; an error exits non-zero with the reason
on stderr.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import signal
import sys
import time
import uuid
from typing import Any

_PR_SET_PDEATHSIG = 1
_MATCH_TIMEOUT_S = 30.0  # a peer that never sees the other's subscriber is broken: bounds a hang only
_STOP_TIMEOUT_S = 10.0  # the echo's time to exit after the stop sentinel
_POOL_SLOTS = 4  # shared memory per provider, in payloads: a sender has at most two buffers in flight


def die_with_parent() -> None:
    """SIGKILL this process if its parent dies (the benchmark, or the initiator for the echo)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


def _config(zenoh: Any, listen: str | None, connect: str | None) -> Any:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    config.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
    config.insert_json5("transport/shared_memory/enabled", "true")
    return config


def _provider(zenoh: Any, size: int) -> Any | None:
    """A POSIX shared-memory provider big enough for a few payloads, or None without SHM API."""
    shm = getattr(zenoh, "shm", None)
    if shm is None:
        return None
    return shm.ShmProvider.default_backend(_POOL_SLOTS * max(size, 4096))


def _put(zenoh: Any, pub: Any, provider: Any | None, data: bytes | bytearray) -> None:
    if provider is None:
        pub.put(bytes(data))
        return
    buf = provider.alloc(len(data), zenoh.shm.BlockOn(zenoh.shm.GarbageCollect()))
    buf[:] = data  # the one copy into shared memory
    pub.put(buf)


def _wait_matching(pub: Any, what: str) -> None:
    deadline = time.monotonic() + _MATCH_TIMEOUT_S
    while not pub.matching_status.matching:
        if time.monotonic() > deadline:
            raise RuntimeError(f"zenoh {what}: no subscriber matched in {_MATCH_TIMEOUT_S:.0f} s")
        time.sleep(0.001)


def _declare(zenoh: Any, session: Any, prefix: str, listen: str, speak: str) -> tuple[Any, Any]:
    sub = session.declare_subscriber(f"{prefix}/{listen}")
    pub = session.declare_publisher(f"{prefix}/{speak}", congestion_control=zenoh.CongestionControl.BLOCK, express=True)
    return sub, pub


def _echo(prefix: str, size: int, cpu: int | None, port: int, ready_fd: int) -> None:
    import zenoh  # the peer environment only

    die_with_parent()
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    zenoh.init_log_from_env_or("error")
    with zenoh.open(_config(zenoh, f"tcp/127.0.0.1:{port}", None)) as session:
        provider = _provider(zenoh, size)
        sub, pub = _declare(zenoh, session, prefix, "ping", "pong")
        os.write(ready_fd, b"r")
        os.close(ready_fd)
        matched = False
        while True:
            payload = sub.recv().payload
            n = len(payload)
            if n == 1 and size != 1:  # the stop sentinel (a 1-byte message on a topic of another size)
                return
            data = payload.to_bytes()  # what a Python subscriber can read: a copy out of shared memory
            if not matched:  # the initiator's reply subscriber must be known before the first reply
                _wait_matching(pub, "echo")
                matched = True
            _put(zenoh, pub, provider, data)
            del payload, data


def _reap(pid: int, grace_s: float) -> int:
    """The echo's wait status: it has ``grace_s`` to exit by itself (after the stop sentinel),
    then it is killed (it would otherwise wait for pings forever)."""
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        time.sleep(0.01)
    os.kill(pid, signal.SIGKILL)
    return os.waitpid(pid, 0)[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, required=True)
    parser.add_argument("--count", type=int, required=True)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--cpus", default="none", help="'A,B': the initiator on A, the echo on B")
    parser.add_argument("--port", type=int, required=True, help="a free TCP port on 127.0.0.1 for the echo to listen on")
    parser.add_argument("--tag", default=uuid.uuid4().hex, help="names this run's key expressions (emos-bench/TAG/...)")
    args = parser.parse_args(argv)
    import numpy as np
    import zenoh

    die_with_parent()
    cpus = None if args.cpus == "none" else tuple(int(c) for c in args.cpus.split(","))
    size = args.size
    prefix = f"emos-bench/{args.tag}"
    ready_r, ready_w = os.pipe()
    pid = os.fork()  # before any zenoh session (and its threads) exists in this process
    if pid == 0:
        os.close(ready_r)
        code = 0
        try:
            _echo(prefix, size, cpus[1] if cpus else None, args.port, ready_w)
        except BaseException as exc:  # noqa: BLE001 - reported, then the child exits
            print(f"zenoh echo: {type(exc).__name__}: {exc}", file=sys.stderr)
            code = 1
        os._exit(code)
    os.close(ready_w)
    if cpus is not None:
        os.sched_setaffinity(0, {cpus[0]})
    zenoh.init_log_from_env_or("error")
    stopped = False
    shm_seen = False
    try:
        if os.read(ready_r, 1) != b"r":
            raise RuntimeError("the zenoh echo process died while starting")
        with zenoh.open(_config(zenoh, None, f"tcp/127.0.0.1:{args.port}")) as session:
            provider = _provider(zenoh, size)
            sub, pub = _declare(zenoh, session, prefix, "pong", "ping")
            _wait_matching(pub, "initiator")
            raw = bytearray(size)  # the numpy payload lives in a bytearray: the one type buf[:] takes
            payload = np.frombuffer(raw, np.uint8)
            payload[:] = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
            seq_bytes = min(8, size)
            total = args.warmup + args.count
            rtts: list[int] = []
            for i in range(total):
                payload[:seq_bytes] = np.frombuffer((i + 1).to_bytes(8, "little")[:seq_bytes], np.uint8)
                start = time.perf_counter_ns()
                _put(zenoh, pub, provider, raw)
                received = sub.recv().payload
                reply = np.frombuffer(received.to_bytes(), np.uint8)
                rtts.append(time.perf_counter_ns() - start)
                if reply.nbytes != size or bytes(reply[:seq_bytes]) != bytes(payload[:seq_bytes]):
                    raise RuntimeError(f"zenoh at {size} B: reply {i} carried the wrong bytes")
                if i == 0:
                    if not np.array_equal(reply, payload):
                        raise RuntimeError(f"zenoh at {size} B: the echo changed the payload")
                    shm_seen = provider is not None and received.as_shm() is not None
                del reply, received
            _put(zenoh, pub, None, b"\0")
            stopped = True
    finally:
        os.close(ready_r)
        status = _reap(pid, _STOP_TIMEOUT_S if stopped else 0.0)
    if status != 0:
        raise RuntimeError(f"zenoh echo process exited with status {status}")
    json.dump({"half_rtt_us": [ns / 2e3 for ns in rtts[args.warmup :]], "shm": shm_seen}, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
