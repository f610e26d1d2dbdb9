"""Where an 8 MiB ping-pong spends its time: EMOS over Zenoh against raw Zenoh, stage by stage.

A diagnostic for ``emos bench net`` (docs/benchmarks-history.md, "EMOS over Zenoh on a quiet machine"):
the same two ends as the benchmark (:class:`emos.tools.bench.net._End`), in two processes joined
over loopback TCP, with ``time.perf_counter_ns`` marks around the send (EMOS: encode, frame and
``put``; and ``put`` alone), the frame check and the decode on Zenoh's thread, and the take
(``EMOS_CODEC=python`` for the Python codec, see emos/msgs/_ccodec.c).
Prints the half round trip's p50 and each stage's median, for the pinging side and the echo::

    python3 scripts/net_stages.py zenoh            # raw Zenoh, 8 MiB
    python3 scripts/net_stages.py emos-zenoh       # EMOS over Zenoh, 8 MiB
    python3 scripts/net_stages.py emos-zenoh 921600
    python3 scripts/net_stages.py --tight 8        # the same stages in a tight loop (warm caches)
    python3 scripts/net_stages.py --floor 8        # raw Zenoh, the least a typed API can do, EMOS

``--floor`` answers "how close to raw Zenoh can a typed API get at all?": in one pair of
processes, interleaved round by round, it measures raw Zenoh, EMOS, and a *typed floor*, raw
Zenoh plus only what any API that hands a component a message object must do per hop: on
receipt, build a ``UInt8MultiArray`` (its layout and a numpy view of the bytes) with no header,
no checks and no codec; on send, take the array's bytes (``tobytes``). Small payloads only.
"""
from __future__ import annotations

import json
import os
import select
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
import uuid

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np

from emos.msgs import UInt8MultiArray
from emos.tools.bench import net as bench
from emos.transport import zenoh_net

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
        # Called from Zenoh's thread: a whole frame's check and decode (one C call when the codec's
        # fast path is built), and a large message's header check.
        zenoh_net.read_message = _timed("check + decode", zenoh_net.read_message)
        zenoh_net.read_frame = _timed("read_frame (split header)", zenoh_net.read_frame)
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
        child.wait(10)
        shutil.rmtree(folder, ignore_errors=True)  # the Zenoh configurations (and the echo's result)
        os._exit(0)


class TypedFloor:
    """One end of the typed floor (see the module doc): a raw Zenoh end whose ``take`` builds
    each message object and whose ``send`` takes the bytes out of one."""

    def __init__(self, config: str, group: str, side: str):
        from emos.msgs.std import MultiArrayLayout

        self._raw = bench._End(config, f"{group}floor", "zenoh", side)  # keys of its own
        self.inbox = self._raw.inbox
        put, new, setattr_ = self._raw.send, object.__new__, object.__setattr__

        def build(data: bytes) -> UInt8MultiArray:
            layout = new(MultiArrayLayout)
            setattr_(layout, "dim", [])
            setattr_(layout, "data_offset", 0)
            msg = new(UInt8MultiArray)
            setattr_(msg, "layout", layout)
            setattr_(msg, "data", np.frombuffer(data, np.uint8))
            return msg

        self.send = lambda msg: put(msg.data.tobytes())
        self.take = lambda: [build(data) for data in self._raw.take()]


FLOOR_ENDS = ("zenoh", "typed floor", "emos-zenoh")


def _floor_ends(config: str, group: str, side: str) -> dict:
    return {name: TypedFloor(config, group, side) if name == "typed floor" else bench._End(config, group, name, side) for name in FLOOR_ENDS}


def floor_echo(config: str, group: str) -> None:
    by_fd = {end.inbox.rfd: end for end in _floor_ends(config, group, "pong").values()}
    last = time.time()
    while time.time() - last < 5.0:  # the ping side is done (or gone)
        for fd in select.select(list(by_fd), [], [], 1.0)[0]:
            os.read(fd, 4096)
            end = by_fd[fd]
            for msg in end.take():
                end.send(msg)
            last = time.time()
    os._exit(0)


def floor(size: int, rounds: int = 8, per_round: int = 150) -> None:
    if size >= 64 * 1024:
        sys.exit("--floor is for small payloads (under 64 KiB): the floor's tobytes would copy a large one")
    folder = tempfile.mkdtemp(prefix="emos-net-floor-")
    port_ping, port_pong = bench._free_port(), bench._free_port()
    ping_conf = bench._config_file(folder, "ping", port_ping, port_pong)
    pong_conf = bench._config_file(folder, "pong", port_pong, port_ping)
    group = f"floor{uuid.uuid4().hex[:6]}"
    child = subprocess.Popen([sys.executable, __file__, "--floor-echo", pong_conf, group])
    try:
        ends = _floor_ends(ping_conf, group, "ping")
        time.sleep(1.0)  # let the sessions connect
        raw = np.random.default_rng(1).integers(0, 256, size, dtype=np.uint8).tobytes()
        msg = UInt8MultiArray(data=np.frombuffer(raw, np.uint8))
        payloads = {"zenoh": raw, "typed floor": msg, "emos-zenoh": msg}
        samples: dict[str, list[float]] = {name: [] for name in FLOOR_ENDS}
        for i in range(rounds):
            for name in FLOOR_ENDS:
                samples[name] += bench._round_trips(ends[name], payloads[name], per_round)[0]
            print(f"round {i + 1}/{rounds}", file=sys.stderr, flush=True)
        base = statistics.median(samples["zenoh"])
        print(f"{size} B, half round trip p50 over {rounds} interleaved rounds of {per_round}:")
        for name in FLOOR_ENDS:
            p50 = statistics.median(samples[name])
            print(f"  {name:12s} {p50:7.1f} us   {p50 - base:+6.1f} us a hop   {100 * (p50 - base) / base:+6.1f} %")
    finally:
        child.kill()
        child.wait(10)
        shutil.rmtree(folder, ignore_errors=True)  # the Zenoh configurations (and the echo's result)
        os._exit(0)


def tight(size: int) -> None:
    """The EMOS stages of one hop run back to back on one message: what they cost warm. From
    ``FrameWriter.SPLIT`` up, as ``ZenohPublisher`` sends it: in two parts (arrays, header)."""
    from emos.msgs import codec
    from emos.transport.netframe import SPLIT_MAGIC, FrameWriter, SplitPayload, encode_framed, read_frame, read_message

    raw = np.random.default_rng(1).integers(0, 256, size, dtype=np.uint8).tobytes()
    msg = UInt8MultiArray(data=np.frombuffer(raw, np.uint8))  # as the benchmark sends it
    fingerprint = UInt8MultiArray._emos_fingerprint
    writer = FrameWriter(fingerprint, "ping")
    if size < FrameWriter.SPLIT:
        frame = bytes(writer.frame(codec.encode(msg), 1))
        payload = read_frame(frame, fingerprint)[2]
        fp = fingerprint.encode()
        read_message(frame, fp, UInt8MultiArray)  # the publisher's names checked once, as on a first frame
        stages = {
            "encode + frame": lambda: writer.frame(codec.encode(msg), 1),
            "read_frame": lambda: read_frame(frame, fingerprint),
            "decode": lambda: codec.decode(UInt8MultiArray, payload),
            "encode_framed (what ZenohPublisher runs)": lambda: encode_framed(msg, writer.header, 1, FrameWriter.SMALL),
            "read_message (what ZenohSubscriber runs)": lambda: read_message(frame, fp, UInt8MultiArray),
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
    if sys.argv[1] == "--floor":
        floor(int(sys.argv[2]) if len(sys.argv) > 2 else 8)
    elif sys.argv[1] == "--floor-echo":
        floor_echo(*sys.argv[2:4])
    elif sys.argv[1] == "--tight":
        tight(int(sys.argv[2]) if len(sys.argv) > 2 else 8)
    elif sys.argv[1] == "--echo":
        echo(*sys.argv[2:6])
    else:
        ping(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 8 << 20)
