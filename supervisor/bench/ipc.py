"""``emos bench ipc``: one-way latency and throughput, publisher process -> subscriber process.

EMOS topics are measured through the real path a component uses (encode into the ring, FIFO
wake-up, uvloop reader, copy out, decode to a numpy array), against ``multiprocessing.Queue`` and
``multiprocessing.Pipe`` carrying the same bytes, in the same run. Latency is the receive time
minus the send time on the shared system clock, with the sender pacing messages (by spinning, see
``_pace``) so that no queue builds up; throughput is messages received per second while the sender sends flat out.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time
from typing import Any

import numpy as np

from emos.supervisor.bench.common import percentiles, table

SIZES = [8, 1024, 65536, 921_600, 8 * 1024 * 1024]
TRANSPORTS = ["emos", "mp_queue", "mp_pipe"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the machine-readable result")
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)), help="payload sizes in bytes, comma-separated")
    parser.add_argument("--transports", default=",".join(TRANSPORTS))
    parser.add_argument("--messages", type=int, default=400, help="latency samples per size (fewer for large payloads)")
    parser.add_argument("--throughput-seconds", type=float, default=1.0)


def _samples_for(size: int, wanted: int) -> int:
    return max(40, min(wanted, int(wanted * 65536 / max(size, 65536))))


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


# ------------------------------------------------------------------ EMOS
def _emos_receiver(topic: str, count: int, ready: Any, out: Any, mode: str, seconds: float) -> None:
    import asyncio

    import uvloop

    from emos.msgs import UInt8MultiArray, codec
    from emos.transport.context import current
    from emos.transport.pubsub import Subscriber
    from emos.transport.waker import Waker

    ctx = current()
    loop = uvloop.new_event_loop()
    asyncio.set_event_loop(loop)
    waker = Waker(ctx)
    sub = Subscriber(ctx, topic, UInt8MultiArray, waker=waker, queue_size=64)
    latencies: list[float] = []
    received = 0
    first = last = 0.0
    done = loop.create_future()

    def on_wake() -> None:
        nonlocal received, first, last
        waker.drain()
        for stamp, raw, _ in sub.take_raw():
            msg = codec.decode(UInt8MultiArray, raw)
            now = time.time_ns()  # received and decoded: the array is usable now
            assert msg.data.nbytes >= 0
            received += 1
            if mode == "latency":
                # ``stamp`` is the ring's record of when publish() was called.
                latencies.append((now - stamp) / 1e3)
                if received >= count and not done.done():
                    done.set_result(None)
            else:
                last = time.monotonic()
                if received == 1:
                    first = last

    loop.add_reader(waker.fd, on_wake)
    ready.send("ready")
    if mode == "latency":
        loop.run_until_complete(asyncio.wait_for(done, 120))
        out.send(latencies)
    else:
        loop.run_until_complete(asyncio.sleep(seconds + 1.0))
        out.send((received, last - first, sub.dropped))
    sub.close()
    waker.close()


def _emos_run(size: int, count: int, mode: str, seconds: float) -> Any:
    from emos.msgs import UInt8MultiArray
    from emos.transport.context import current
    from emos.transport.pubsub import Publisher

    ctx = current()
    topic = f"/bench/ipc_{size}_{mode}"
    payload = np.random.randint(0, 255, size, dtype=np.uint8)
    recv_end, send_end = mp.Pipe(duplex=False)
    ready_r, ready_w = mp.Pipe(duplex=False)
    proc = mp.get_context("fork").Process(target=_emos_receiver, args=(topic, count, ready_w, send_end, mode, seconds))
    proc.start()
    ready_r.recv()
    pub = Publisher(ctx, topic, UInt8MultiArray, publisher_id="bench", depth=16)
    msg = UInt8MultiArray(data=payload)
    # Warm up: grow the ring to the payload size and fault its pages in.
    for _ in range(20):
        pub.publish(msg)
        time.sleep(0.002)
    time.sleep(0.05)
    try:
        if mode == "latency":
            gap = _gap_for(size)
            for _ in range(count):
                pub.publish(msg)
                _pace(gap)
            return recv_end.recv()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            pub.publish(msg)
        return recv_end.recv()
    finally:
        proc.join(30)
        pub.close()


# ------------------------------------------------------------------ multiprocessing
def _mp_receiver(conn: Any, kind: str, count: int, out: Any, mode: str) -> None:
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
    ctx = mp.get_context("fork")
    payload = np.random.randint(0, 255, size, dtype=np.uint8).tobytes()
    if kind == "mp_queue":
        chan = ctx.Queue(maxsize=64)
        send, conn = chan.put, chan
    else:
        r, w = ctx.Pipe(duplex=False)
        send, conn = w.send, r
    recv_end, send_end = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_mp_receiver, args=(conn, kind, count, send_end, mode))
    proc.start()
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
    proc.join(30)
    return result


def measure(transports: list[str], sizes: list[int], messages: int, seconds: float, progress: bool = True) -> list[dict[str, Any]]:
    results = []
    for size in sizes:
        for transport in transports:
            count = _samples_for(size, messages)
            if progress:
                print(f"  {transport:>8} {size:>9} B: latency ({count} msgs)...", end="", flush=True)
            if transport == "emos":
                lat = _emos_run(size, count, "latency", seconds)
                got, span, dropped = _emos_run(size, count, "throughput", seconds)
            else:
                lat = _mp_run(transport, size, count, "latency", seconds)
                got, span, dropped = _mp_run(transport, size, count, "throughput", seconds)
            lat = lat[min(5, len(lat) // 10):]
            p = percentiles(lat)
            rate = got / span if span > 0 else float("nan")
            if progress:
                print(f" p50 {p['p50']:.1f} us, p99 {p['p99']:.1f} us; {rate:,.0f} msg/s", flush=True)
            results.append({"transport": transport, "payload_bytes": size, "p50_us": round(p["p50"], 2), "p99_us": round(p["p99"], 2), "msgs_per_s": round(rate, 1), "dropped": dropped})
    return results


def run(args: argparse.Namespace) -> int:
    sizes = [int(s) for s in args.sizes.split(",") if s]
    transports = [t for t in args.transports.split(",") if t]
    bad = [t for t in transports if t not in TRANSPORTS]
    if bad:
        print(f"emos bench ipc: unknown transport(s) {bad}; choose from {TRANSPORTS}")
        return 2
    if not args.json:
        print(f"emos bench ipc on {os.cpu_count()} cores: payloads {sizes}")
    results = measure(transports, sizes, args.messages, args.throughput_seconds, progress=not args.json)
    if args.json:
        print(json.dumps({"results": results}))
        return 0
    print()
    print(table(results, [("transport", "transport", ""), ("payload_bytes", "bytes", ",d"), ("p50_us", "p50 us", ".1f"), ("p99_us", "p99 us", ".1f"), ("msgs_per_s", "msg/s", ",.0f")]))
    by = {(r["transport"], r["payload_bytes"]): r for r in results}
    print()
    for size in sizes:
        e, p = by.get(("emos", size)), by.get(("mp_pipe", size))
        if e and p and e["p50_us"] > 0:
            print(f"  {size:>9} B: pipe p50 / emos p50 = {p['p50_us'] / e['p50_us']:.1f}x")
    return 0
