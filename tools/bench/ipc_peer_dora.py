"""dora-rs ping-pong for ``emos bench ipc --peers dora``: run by the peer environment's Python
(``ipc_peers.py`` installs dora-rs and dora-rs-cli there; never imported by EMOS, never a
dependency of it).

A dataflow of two Python nodes, ``ping`` and ``pong``, started the way a dora user starts one:
``dora run dataflow.yml`` (dora-rs-cli 1.x runs the daemon inside that command; no coordinator,
no ``dora up``). The same method as the EMOS ping-pong (``ipc_pingpong.py``): ``ping`` stamps a
numpy payload and sends it as an Arrow array (``node.send_output``; dora copies it into a
shared-memory sample), ``pong`` sends the input it receives back as its own output, and ``ping``
stops the clock once the reply is a numpy array (``to_numpy(zero_copy_only=True)``: a view of
the received sample); a sample is half that round trip. The nodes pin themselves to their CPUs
before dora starts in them (``ping`` on A, ``pong`` on B); the daemon (the ``dora run`` process)
may run on either. ``ping`` writes its samples to a file in the run's folder, and this launcher
prints ``{"half_rtt_us": [...]}``; an error exits non-zero with the reason on stderr.

Files. Everything of a run is in ``--root``, a folder the benchmark made for it: the dataflow,
the samples, dora's ``out/`` logs and session file, the launcher's ``dora.log``. dora 1.1 moves
large outputs between nodes through zenoh shared memory (``/dev/shm/<number>.zenoh``): the
benchmark (``ipc_peers.remove_zenoh_files``) removes the new segments no live process holds, and
the folder, after the run, whether it ended well or was killed.

Usage: ``python ipc_peer_dora.py --size N --count N --warmup N --cpus A,B --root DIR`` (the
launcher); ``--role ping|pong`` is how the dataflow starts the nodes.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

_PR_SET_PDEATHSIG = 1
_REPLY_TIMEOUT_S = 60.0  # one reply; only a dead or hung pong reaches it
_MIN_POOL_BYTES = 32 << 20
SAMPLES = "samples.json"
DATAFLOW = "dataflow.yml"
LOG = "dora.log"


def die_with_parent() -> None:
    """SIGKILL this process if its parent dies: the launcher with the benchmark, ``dora run``
    with the launcher. (Not the nodes: their parent is one of ``dora run``'s threads, which may
    end while the dataflow runs; dora stops its nodes itself when it ends.)"""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


def dataflow(python: str, script: str, args: argparse.Namespace) -> dict[str, Any]:
    """The two-node dataflow (JSON is YAML, and needs no quoting rules of its own)."""
    cpus = args.cpus.split(",") if args.cpus != "none" else ["none", "none"]
    common = f"{script} --size {args.size}"
    for part in (python, script, args.root):
        if any(c.isspace() for c in part):
            raise RuntimeError(f"dora peer: the path {part!r} has white space, which dora's node arguments cannot carry")
    ping_args = f"{common} --role ping --count {args.count} --warmup {args.warmup} --cpu {cpus[0]} --out {Path(args.root) / SAMPLES}"
    env = {"DORA_NODE_SHM_POOL_SIZE": shm_pool_bytes(args.size)}
    return {"nodes": [
        {"id": "ping", "path": python, "args": ping_args, "inputs": {"pong": "pong/pong"}, "outputs": ["ping"], "env": env},
        {"id": "pong", "path": python, "args": f"{common} --role pong --cpu {cpus[1]}", "inputs": {"ping": "ping/ping"}, "outputs": ["pong"], "env": env},
    ]}


def shm_pool_bytes(size: int) -> int:
    """Each node's zenoh shared-memory pool (``DORA_NODE_SHM_POOL_SIZE``), sized as a dora user
    sizes it for frames this big: room for a few outputs in flight. An output that does not fit
    the default pool falls back to a shared-memory region per message through
    the daemon, which measured 45-80 ms per 8 MiB hop instead of about 1.2 ms."""
    return max(_MIN_POOL_BYTES, 5 * size)


def _pin(cpu: str) -> None:
    if cpu != "none":
        os.sched_setaffinity(0, {int(cpu)})


def _next_input(node: Any, wanted: str) -> Any:
    while True:
        event = node.next(timeout=_REPLY_TIMEOUT_S)
        if event is None:
            raise RuntimeError(f"dora ping: no {wanted!r} input in {_REPLY_TIMEOUT_S:.0f} s (the event stream ended or timed out)")
        kind = event["type"]
        if kind == "INPUT" and event["id"] == wanted:
            return event
        if kind in ("STOP", "ERROR"):
            raise RuntimeError(f"dora ping: got {kind} while waiting for {wanted!r}: {event.get('error', '')}")


def ping(args: argparse.Namespace) -> int:
    _pin(args.cpu)
    import numpy as np
    import pyarrow as pa  # type: ignore[import-not-found]  # the peer environment only
    from dora import Node  # type: ignore[import-not-found]  # the peer environment only

    node = Node()
    size = args.size
    payload = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
    seq_bytes = min(8, size)
    total = args.warmup + args.count
    rtts: list[int] = []
    for i in range(total):
        payload[:seq_bytes] = np.frombuffer((i + 1).to_bytes(8, "little")[:seq_bytes], np.uint8)
        start = time.perf_counter_ns()
        node.send_output("ping", pa.array(payload))
        event = _next_input(node, "pong")
        reply = event["value"].to_numpy(zero_copy_only=True)
        rtts.append(time.perf_counter_ns() - start)
        if reply.nbytes != size or bytes(reply[:seq_bytes]) != bytes(payload[:seq_bytes]):
            raise RuntimeError(f"dora at {size} B: reply {i} carried the wrong bytes")
        if i == 0 and not np.array_equal(reply, payload):
            raise RuntimeError(f"dora at {size} B: the echo changed the payload")
        del reply, event
    out = Path(args.out)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps({"half_rtt_us": [ns / 2e3 for ns in rtts[args.warmup :]]}))
    tmp.replace(out)  # whole or absent: the launcher never reads half a file
    return 0  # exiting closes ping/ping, which ends pong's event stream


def pong(args: argparse.Namespace) -> int:
    _pin(args.cpu)
    from dora import Node  # the peer environment only

    node = Node()
    for event in node:
        if event["type"] == "INPUT":
            node.send_output("pong", event["value"])
        elif event["type"] == "STOP":
            break
    return 0


def launch(args: argparse.Namespace) -> int:
    die_with_parent()
    root = Path(args.root)
    dora = args.dora or str(Path(sys.executable).with_name("dora"))
    if not Path(dora).exists():
        raise RuntimeError(f"dora peer: the dora command ({dora}) is missing; install dora-rs-cli into the peer environment")
    if args.cpus != "none":  # the daemon is neither end: let it run on either of the two CPUs
        os.sched_setaffinity(0, {int(c) for c in args.cpus.split(",")})
    flow = root / DATAFLOW
    flow.write_text(json.dumps(dataflow(sys.executable, str(Path(__file__).resolve()), args), indent=1))
    with open(root / LOG, "wb") as log:
        done = subprocess.run([dora, "run", "--log-level", "error", str(flow)], cwd=str(root), stdout=log, stderr=subprocess.STDOUT,
                              stdin=subprocess.DEVNULL, check=False, preexec_fn=die_with_parent)
    samples = root / SAMPLES
    if done.returncode != 0 or not samples.exists():
        tail = (root / LOG).read_text(errors="replace").strip().splitlines()[-6:]
        raise RuntimeError(f"dora run exited {done.returncode}" + ("" if samples.exists() else " without samples") + ": " + " | ".join(tail))
    sys.stdout.write(samples.read_text())
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--role", choices=["launch", "ping", "pong"], default="launch")
    parser.add_argument("--size", type=int, required=True)
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--cpus", default="none", help="launcher: 'A,B', ping on A, pong on B")
    parser.add_argument("--cpu", default="none", help="a node: its CPU")
    parser.add_argument("--root", help="launcher: the run's folder (made by the benchmark)")
    parser.add_argument("--dora", help="launcher: the dora command (default: beside this Python)")
    parser.add_argument("--out", help="ping: where to write the samples")
    args = parser.parse_args(argv)
    try:
        if args.role == "ping":
            return ping(args)
        if args.role == "pong":
            return pong(args)
        if not args.root or args.count < 1:
            parser.error("the launcher needs --root and --count")
        return launch(args)
    except RuntimeError as exc:
        print(str(exc), file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
