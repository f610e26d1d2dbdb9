"""``emos bench ipc``, one way: a sender process and a receiver process.

Two measurements live here. The ``oneway`` latency method: the receiver subtracts the send
stamp (shared system clock) from its receive time while the sender paces messages by spinning
(``_pace``), so no queue builds up. Throughput, used by every method: messages received per
second while the sender sends flat out.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from emos.tools.bench.ipc_common import FORK, random_payload, remove_topic, start_child, stop_child, wait_ready

# Leading samples dropped from a one-way run: the first messages fault pages in.
_WARMUP_DIVISOR = 10
_WARMUP_MAX = 5


def _gap_for(size: int) -> float:
    # Leave the receiver idle between messages: latency, not queueing, is measured.
    return max(0.0015, size / 1.5e9 * 6)


def _pace(gap: float) -> None:
    """Wait by spinning, for every transport alike. A sleeping sender's CPU goes idle and, on a
    virtual machine, comes back with cold caches tens of microseconds later: that is the
    scheduler's latency, not the transport's, and it would be charged to the next message.
    ``sleep(0)`` releases the GIL on every turn, so helper threads (``multiprocessing.Queue``'s
    feeder) run as they would with a real sleep."""
    end = time.perf_counter() + gap
    while time.perf_counter() < end:
        time.sleep(0)


def _drop_warmup(latencies: list[float]) -> list[float]:
    return latencies[min(_WARMUP_MAX, len(latencies) // _WARMUP_DIVISOR) :]


# ------------------------------------------------------------------ EMOS
def _emos_receiver(topic: str, count: int, ready: Any, out: Any, mode: str, seconds: float) -> None:
    import asyncio

    import uvloop

    from emos.core.node import wake_spin_setting
    from emos.msgs import UInt8MultiArray, codec
    from emos.transport.context import current
    from emos.transport.pubsub import Subscriber
    from emos.transport.waker import Waker

    ctx = current()
    loop = uvloop.new_event_loop()
    asyncio.set_event_loop(loop)
    waker = Waker(ctx, spin_us=wake_spin_setting())  # as a component's node does
    sub = Subscriber(ctx, topic, UInt8MultiArray, waker=waker, queue_size=64)
    latencies: list[float] = []
    received = 0
    first = last = 0.0
    done = loop.create_future()

    def handle() -> None:
        nonlocal received, first, last
        for stamp, raw, _ in sub.take_raw():
            msg = codec.decode(UInt8MultiArray, raw)
            now = time.time_ns()  # received and decoded: the array is usable now
            assert msg.data.nbytes >= 0
            received += 1
            if mode == "latency":
                # ``stamp`` is the ring's record of when publish() was called.
                latencies.append((now - stamp) / 1e3)
                # Lapped messages count as arrived (a receiver descheduled on a busy machine
                # misses some): waiting for all of them would wait forever.
                if received + sub.dropped >= count and not done.done():
                    done.set_result(None)
            else:
                last = time.monotonic()
                if received == 1:
                    first = last

    try:
        # A node's wake-up path: drain, handle, linger for more (waker.serve), so a flat-out
        # sender meets the receiver users get, not one that parks after every message.
        loop.add_reader(waker.fd, waker.serve, handle, sub.has_news)
        ready.send("ready")
        if mode == "latency":
            loop.run_until_complete(asyncio.wait_for(done, 120))
            out.send(latencies)
        else:
            loop.run_until_complete(asyncio.sleep(seconds + 1.0))
            out.send((received, last - first, sub.dropped))
    finally:
        loop.remove_reader(waker.fd)
        loop.close()
        sub.close()
        waker.close()


def _emos_run(size: int, count: int, mode: str, seconds: float, depth: int = 16) -> Any:
    from emos.msgs import UInt8MultiArray
    from emos.transport.context import current
    from emos.transport.pubsub import Publisher

    ctx = current()  # before forking: the receiver must join this run to see the topic
    topic = f"/bench/ipc_{size}_{mode}"
    recv_end, send_end = FORK.Pipe(duplex=False)
    ready_r, ready_w = FORK.Pipe(duplex=False)
    proc = start_child(_emos_receiver, (topic, count, ready_w, send_end, mode, seconds), "emos:bench-rx")
    ready_w.close()
    send_end.close()
    pub = None
    try:
        wait_ready(ready_r, proc)
        pub = Publisher(ctx, topic, UInt8MultiArray, publisher_id="bench", depth=depth)
        msg = UInt8MultiArray(data=random_payload(size))
        # Warm up: grow the ring to the payload size and fault its pages in.
        for _ in range(20):
            pub.publish(msg)
            time.sleep(0.002)
        time.sleep(0.05)
        if mode == "latency":
            gap = _gap_for(size)
            for _ in range(count):
                pub.publish(msg)
                _pace(gap)
            return _drop_warmup(recv_end.recv())
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            pub.publish(msg)
        return recv_end.recv()
    finally:
        stop_child(proc, 30.0)
        if pub is not None:
            pub.close()
        remove_topic(ctx, topic)
        recv_end.close()
        ready_r.close()


# ------------------------------------------------------------------ multiprocessing
def _mp_receiver(conn: Any, kind: str, count: int, out: Any, mode: str) -> None:
    import numpy as np

    get = conn.get if kind == "mp_queue" else conn.recv
    latencies: list[float] = []
    received, first, last = 0, 0.0, 0.0
    while True:
        item = get()
        if item is None:
            break
        sent, data = item
        arr = np.frombuffer(data, dtype=np.uint8)
        now = time.time_ns()
        assert arr.nbytes >= 0
        received += 1
        if mode == "latency":
            latencies.append((now - sent) / 1e3)
        else:
            last = time.monotonic()
            if received == 1:
                first = last
    out.send(latencies if mode == "latency" else (received, last - first, 0))


def _mp_run(kind: str, size: int, count: int, mode: str, seconds: float) -> Any:
    payload = random_payload(size).tobytes()
    queue = None
    send: Callable[[Any], None]  # the sending end's put or send
    conn: Any  # the receiving end, a Queue or a Connection: _mp_receiver reads either
    if kind == "mp_queue":
        queue = FORK.Queue(maxsize=64)
        send, conn = queue.put, queue
    else:
        r, w = FORK.Pipe(duplex=False)
        send, conn = w.send, r
    recv_end, send_end = FORK.Pipe(duplex=False)
    proc = start_child(_mp_receiver, (conn, kind, count, send_end, mode), "emos:bench-rx")
    send_end.close()
    try:
        if mode == "latency":
            gap = _gap_for(size)
            for _ in range(count):
                send((time.time_ns(), payload))
                _pace(gap)
        else:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                send((time.time_ns(), payload))
        send(None)
        result = recv_end.recv()
    finally:
        exit_code = stop_child(proc, 30.0)
        recv_end.close()
        if queue is not None:
            if exit_code != 0:
                queue.cancel_join_thread()  # nobody reads what is left: do not wait to flush it
            # No thread may outlive a measurement: the next one forks.
            queue.close()
            queue.join_thread()
    return _drop_warmup(result) if mode == "latency" else result


# ------------------------------------------------------------------ entry points
def latency_us(transport: str, size: int, count: int, depth: int = 16) -> list[float]:
    """One-way latencies in microseconds, paced sender, warm-up dropped; ``depth``: EMOS ring history."""
    if transport == "emos":
        return _emos_run(size, count, "latency", 0.0, depth)
    return _mp_run(transport, size, count, "latency", 0.0)


def throughput(transport: str, size: int, seconds: float) -> tuple[int, float, int]:
    """``(messages received, seconds between first and last, dropped)`` with the sender flat out."""
    if transport == "emos":
        return _emos_run(size, 0, "throughput", seconds)
    return _mp_run(transport, size, 0, "throughput", seconds)
