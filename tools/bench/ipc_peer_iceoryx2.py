"""iceoryx2 ping-pong for ``emos bench ipc --peers iceoryx2``: run by the peer environment's
Python (``ipc_peers.py`` installs it; never imported by EMOS, never a dependency of it).

The same method as the EMOS ping-pong (``ipc_pingpong.py``): the initiator stamps a numpy
payload, copies it into a loaned sample and sends it; the echo copies the received sample into
a loaned sample of its own and sends it back; the initiator stops the clock once the reply is a
numpy array (a view of the received sample), and a sample is half that round trip. Both ends
are pinned to their CPUs. ``--wait event``: each send is followed by a notification on an event
service and the receiver blocks in ``Listener.blocking_wait`` (iceoryx2's blocking wait);
``--wait poll``: the receiver spins on ``Subscriber.receive`` (with ``sched_yield``).
Prints ``{"half_rtt_us": [...]}`` on stdout; an error exits non-zero with the reason on stderr.

Files. iceoryx2 keeps its services, nodes and a node-management record in files: shared memory
in ``/dev/shm`` and lock and detail files under its root path (``/tmp/iceoryx2``), some of them
(the 16 B ``...global_mgmt`` record) outliving every node. So both processes use a config of
their own: every file name starts with ``--prefix`` (``iox2emos<tag>_``, the tag of this run's
service names ``emos-bench/<tag>/...``) and the root path is ``--root`` (a directory the
benchmark made for this run). The benchmark (``ipc_peers.remove_iceoryx2_files``) then removes
exactly those after the run, whether it ended well or was killed.
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


def _node(iox2: Any, file_prefix: str, root: str) -> Any:
    """A node whose files carry ``file_prefix`` and live under ``root`` (module doc, "Files")."""
    config = iox2.config.default()
    config.global_cfg.prefix = iox2.FileName.new(file_prefix)
    config.global_cfg.root_path = iox2.Path.new(root.rstrip("/") + "/")
    return iox2.NodeBuilder.new().config(config).create(iox2.ServiceType.Ipc)


def _services(node: Any, iox2: Any, prefix: str, size: int) -> dict[str, Any]:
    slice_u8 = iox2.Slice[ctypes.c_uint8]
    out = {}
    for name in ("ping", "pong"):
        out[name] = node.service_builder(iox2.ServiceName.new(f"{prefix}/{name}")).publish_subscribe(slice_u8).open_or_create()
        out[name + "_event"] = node.service_builder(iox2.ServiceName.new(f"{prefix}/{name}_event")).event().open_or_create()
    return out


def _send(pub: Any, src_ptr: int, n: int, notifier: Any | None) -> None:
    sample = pub.loan_slice_uninit(max(n, 1))
    if n:
        ctypes.memmove(sample.payload_ptr, src_ptr, n)
    sample.assume_init().send()
    if notifier is not None:
        notifier.notify()


def _receive(sub: Any, listener: Any | None) -> Any:
    while True:
        sample = sub.receive()
        if sample is not None:
            return sample
        if listener is not None:
            listener.blocking_wait()
        else:
            os.sched_yield()


def _echo(prefix: str, size: int, wait: str, cpu: int | None, ready_fd: int, file_prefix: str, root: str) -> None:
    import iceoryx2 as iox2  # type: ignore[import-not-found]  # the peer environment only

    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    node = _node(iox2, file_prefix, root)
    s = _services(node, iox2, prefix, size)
    sub = s["ping"].subscriber_builder().create()
    pub = s["pong"].publisher_builder().initial_max_slice_len(max(size, 1)).create()
    listener = s["ping_event"].listener_builder().create() if wait == "event" else None
    notifier = s["pong_event"].notifier_builder().create() if wait == "event" else None
    os.write(ready_fd, b"r")
    os.close(ready_fd)
    while True:
        sample = _receive(sub, listener)
        payload = sample.payload()
        n = payload.len()
        if n == 1 and size != 1:  # the stop sentinel (a 1-byte sample on a topic of another size)
            return
        _send(pub, payload.as_ptr(), n, notifier)
        del payload, sample


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, required=True)
    parser.add_argument("--count", type=int, required=True)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--wait", choices=["event", "poll"], default="event")
    parser.add_argument("--cpus", default="none", help="'A,B': the initiator on A, the echo on B")
    parser.add_argument("--tag", default=uuid.uuid4().hex, help="names this run's services (emos-bench/TAG/...)")
    parser.add_argument("--prefix", help="the start of every file name iceoryx2 makes (default iox2emosTAG_)")
    parser.add_argument("--root", default="/tmp/iceoryx2", help="iceoryx2's root path for its lock and detail files")
    args = parser.parse_args(argv)
    import iceoryx2 as iox2
    import numpy as np

    iox2.set_log_level(iox2.LogLevel.Error)
    cpus = None if args.cpus == "none" else tuple(int(c) for c in args.cpus.split(","))
    size = args.size
    prefix = f"emos-bench/{args.tag}"
    file_prefix = args.prefix or f"iox2emos{args.tag}_"
    ready_r, ready_w = os.pipe()
    pid = os.fork()  # before any iceoryx2 node exists in this process
    if pid == 0:
        os.close(ready_r)
        code = 0
        try:
            _echo(prefix, size, args.wait, cpus[1] if cpus else None, ready_w, file_prefix, args.root)
        except BaseException as exc:  # noqa: BLE001 - reported, then the child exits
            print(f"iceoryx2 echo: {type(exc).__name__}: {exc}", file=sys.stderr)
            code = 1
        os._exit(code)
    os.close(ready_w)
    if cpus is not None:
        os.sched_setaffinity(0, {cpus[0]})
    stopped = False
    try:
        if os.read(ready_r, 1) != b"r":
            raise RuntimeError("the iceoryx2 echo process died while starting")
        node = _node(iox2, file_prefix, args.root)
        s = _services(node, iox2, prefix, size)
        pub = s["ping"].publisher_builder().initial_max_slice_len(max(size, 1)).create()
        sub = s["pong"].subscriber_builder().create()
        notifier = s["ping_event"].notifier_builder().create() if args.wait == "event" else None
        listener = s["pong_event"].listener_builder().create() if args.wait == "event" else None
        payload = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
        seq_bytes = min(8, size)
        total = args.warmup + args.count
        rtts: list[int] = []
        for i in range(total):
            payload[:seq_bytes] = np.frombuffer((i + 1).to_bytes(8, "little")[:seq_bytes], np.uint8)
            start = time.perf_counter_ns()
            _send(pub, payload.ctypes.data, size, notifier)
            sample = _receive(sub, listener)
            reply = np.frombuffer(sample.payload().as_memory_view(), np.uint8)
            rtts.append(time.perf_counter_ns() - start)
            if reply.nbytes != size or bytes(reply[:seq_bytes]) != bytes(payload[:seq_bytes]):
                raise RuntimeError(f"iceoryx2 at {size} B: reply {i} carried the wrong bytes")
            if i == 0 and not np.array_equal(reply, payload):
                raise RuntimeError(f"iceoryx2 at {size} B: the echo changed the payload")
            del reply, sample
        stop = np.zeros(1, np.uint8)
        _send(pub, stop.ctypes.data, 1, notifier)
        stopped = True
    finally:
        os.close(ready_r)
        if not stopped:  # we failed before the stop sentinel: the echo would wait for pings forever
            os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
    if status != 0:
        raise RuntimeError(f"iceoryx2 echo process exited with status {status}")
    json.dump({"half_rtt_us": [ns / 2e3 for ns in rtts[args.warmup :]]}, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
