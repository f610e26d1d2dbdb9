"""Where an 8 MiB ping-pong spends its time: EMOS over Zenoh against raw Zenoh, stage by stage.

A diagnostic for ``emos bench net`` (docs/benchmarks.md, "EMOS over Zenoh on a quiet machine"):
the same two ends as the benchmark (:class:`supervisor.bench.net._End`), in two processes joined
over loopback TCP, with ``time.perf_counter_ns`` marks around the send (EMOS: encode, frame and
``put``; and ``put`` alone), the frame check on Zenoh's thread and the take. Prints the half round
trip's p50 and each stage's median, for the pinging side and the echo::

    python3 scripts/net_stages.py zenoh            # raw Zenoh, 8 MiB
    python3 scripts/net_stages.py emos-zenoh       # EMOS over Zenoh, 8 MiB
    python3 scripts/net_stages.py emos-zenoh 921600
    python3 scripts/net_stages.py --tight 8        # the same stages in a tight loop (warm caches)
"""
from __future__ import annotations

import json
import os
import select
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
import uuid

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from emos.msgs import UInt8MultiArray  # noqa: E402
from emos.transport import zenoh_net  # noqa: E402
from supervisor.bench import net as bench  # noqa: E402

ROUND_TRIPS = 60
clock = time.perf_counter_ns
marks: dict[str, list[float]] = {}


def _timed(name, fn):
    def wrapper(*args, **kwargs):
        t0 = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            marks.setdefault(name, []).append((clock() - t0) / 1000.0)
    return wrapper


def instrument(end: bench._End, transport: str) -> None:
    end.send = _timed("send", end.send)
    if transport == "emos-zenoh":
        end.take = _timed("take", end.take)
        zenoh_net.read_frame = _timed("read_frame", zenoh_net.read_frame)  # called from Zenoh's thread
        inner = end._pub._pub
        end._pub._pub = type("TimedPut", (), {"put": staticmethod(_timed("put", inner.put))})()


def medians() -> dict[str, float]:
    return {k: round(statistics.median(v), 1) for k, v in marks.items()}


def echo(transport: str, config: str, group: str, out: str) -> None:
    end = bench._End(config, group, transport, "pong")
    instrument(end, transport)
    echoed, deadline = 0, time.time() + 60
    while time.time() < deadline:
        readable, _, _ = select.select([end.inbox.rfd], [], [], 3.0)
        if not readable:
            if echoed:
                break  # the ping side is done
            continue
        os.read(end.inbox.rfd, 4096)
        for msg in end.take():
            end.send(msg)
            echoed += 1
    with open(out, "w") as f:
        json.dump(medians(), f)
    os._exit(0)  # Zenoh's threads can hold a normal exit


def ping(transport: str, size: int) -> None:
    folder = tempfile.mkdtemp(prefix="emos-net-stages-")
    port_ping, port_pong = bench._free_port(), bench._free_port()
    ping_conf = bench._config_file(folder, "ping", port_ping, port_pong)
    pong_conf = bench._config_file(folder, "pong", port_pong, port_ping)
    group, out = f"stages{uuid.uuid4().hex[:6]}", os.path.join(folder, "echo.json")
    child = subprocess.Popen([sys.executable, __file__, "--echo", transport, pong_conf, group, out])
    try:
        end = bench._End(ping_conf, group, transport, "ping")
        instrument(end, transport)
        time.sleep(1.0)  # let the sessions connect
        data = np.random.default_rng(1).integers(0, 256, size, dtype=np.uint8)
        raw = data.tobytes()  # as in the benchmark: the EMOS message's array is a view of these bytes
        payload = UInt8MultiArray(data=np.frombuffer(raw, np.uint8)) if transport == "emos-zenoh" else raw
        samples, lost = bench._round_trips(end, payload, ROUND_TRIPS)
        child.wait(20)
        print(f"{transport} {size} B: half round trip p50 {statistics.median(samples):.0f} us ({lost} lost)")
        print("  ping side:", medians())
        with open(out) as f:
            print("  echo side:", json.load(f))
    except BaseException:
        import traceback

        traceback.print_exc()  # os._exit below would swallow it
        raise
    finally:
        child.kill()
        os._exit(0)


def tight(size: int) -> None:
    """The EMOS stages of one hop run back to back on one message: what they cost warm. From
    ``FrameWriter.SPLIT`` up, as ``ZenohPublisher`` sends it: in two parts (arrays, header)."""
    from emos.msgs import codec
    from emos.transport.netframe import SPLIT_MAGIC, FrameWriter, SplitPayload, read_frame

    raw = np.random.default_rng(1).integers(0, 256, size, dtype=np.uint8).tobytes()
    msg = UInt8MultiArray(data=np.frombuffer(raw, np.uint8))  # as the benchmark sends it
    fingerprint = UInt8MultiArray._emos_fingerprint
    writer = FrameWriter(fingerprint, "ping")
    if size < FrameWriter.SPLIT:
        frame = bytes(writer.frame(codec.encode(msg), 1))
        payload = read_frame(frame, fingerprint)[2]
        stages = {
            "encode + frame": lambda: writer.frame(codec.encode(msg), 1),
            "read_frame": lambda: read_frame(frame, fingerprint),
            "decode": lambda: codec.decode(UInt8MultiArray, payload),
        }
    else:
        arrays, head = writer.split(codec.encode(msg), 1)
        split = SplitPayload(read_frame(head, fingerprint, SPLIT_MAGIC)[2], arrays)
        stages = {
            "encode + split": lambda: writer.split(codec.encode(msg), 1),
            "read_frame (header)": lambda: read_frame(head, fingerprint, SPLIT_MAGIC),
            "decode": lambda: split.decode(UInt8MultiArray),
        }
    number = max(20, 20000 * 8 // max(size, 8))
    for name, fn in stages.items():
        best = min(timeit.repeat(fn, number=number, repeat=7)) / number * 1e6
        print(f"{size} B {name}: {best:.1f} us (best of 7 x {number})")


if __name__ == "__main__":
    if sys.argv[1] == "--tight":
        tight(int(sys.argv[2]) if len(sys.argv) > 2 else 8)
    elif sys.argv[1] == "--echo":
        echo(*sys.argv[2:6])
    else:
        ping(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 8 << 20)
