"""Small messages through the rings in one C call each way (``_ccodec.ring_publish`` and
``ring_take``, used by :mod:`emos.transport.pubsub`; docs/ipc.md, "Small messages").

The C path must write exactly the frames the Python path writes, keep the ring's protocol
(seqlock, pins, lapped readers, a writer SIGKILLed mid-write) and its distrust of the segment,
and leave everything it does not handle (big frames, a ring to grow, a pinned slot, damaged
bytes) to the Python path, with the ring untouched. And it must actually take the Python
interpreter out of the small-message path: counted in Python calls, not in time.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import random
import signal
import zlib
from pathlib import Path

import numpy as np
import pytest

from emos import msgs as M
from emos.msgs import codec
from emos.transport import pubsub
from emos.transport import ring as R
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber
from tests.python_calls import python_calls
from tests.runtime.test_ccodec import SAMPLES

needs_c = pytest.mark.skipif(codec.C_CODEC is None, reason="the C codec is not built (no compiler at install, or EMOS_CODEC=python)")


def _slot_bytes(ring: R.Ring, n: int) -> bytes:
    status, payload, _ = ring.read(n)
    assert status == R.OK
    assert payload is not None
    return bytes(payload)


def _python_frame(msg) -> bytes:
    return codec.encode_python(msg).to_bytes()


@needs_c
@pytest.mark.unit
def test_every_message_type_is_written_byte_for_byte_as_the_python_path_writes_it(ctx):
    """Every registered type, default and random contents: the slot holds the Python codec's
    frame (padding zeroed), the stamp given, and the numbers run on."""
    small = [m for m in SAMPLES if codec.encode_python(m).nbytes <= pubsub.SMALL_FRAME_BYTES]
    assert len(small) > 50
    by_type: dict[type, list] = {}
    for m in small:
        by_type.setdefault(type(m), []).append(m)
    for cls, msgs in by_type.items():
        pub = Publisher(ctx, f"/bytes/{cls.__name__}", cls, publisher_id="w", depth=16, capacity=pubsub.SMALL_FRAME_BYTES)
        for i, m in enumerate(msgs):
            ring = pub.ring
            got = pubsub._ring_publish(m, ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, 1000 + i,
                                       pubsub.SMALL_FRAME_BYTES)
            if got is NotImplemented:  # a value the C encoder leaves to Python: the ring is untouched
                assert ring.head == i
                pub.publish(m)
                continue
            assert got == i, f"{cls.__name__}: message number"
            assert _slot_bytes(ring, i) == _python_frame(m), f"{cls.__name__} #{i}"
            assert ring.stamp_of(i) == 1000 + i
            assert ring.head == i + 1
        pub.close()


@needs_c
@pytest.mark.unit
def test_subscribers_read_the_same_messages_with_and_without_the_c_path(ctx, monkeypatch):
    """One subscriber reads through ``ring_take``, one through the Python path: the same payloads,
    stamps, order, read-only buffers and drop counts, also when the writer laps them."""
    pub = Publisher(ctx, "/same", M.UInt8MultiArray, publisher_id="w", depth=8)
    fast = Subscriber(ctx, "/same", M.UInt8MultiArray, queue_size=64)
    slow = Subscriber(ctx, "/same", M.UInt8MultiArray, queue_size=64)
    rng = np.random.default_rng(3)

    def both() -> tuple[list, list]:
        a = fast.take_raw()
        monkeypatch.setattr(pubsub, "_ring_take", None)
        b = slow.take_raw()
        monkeypatch.undo()
        return a, b

    for burst in (1, 5, 8, 13, 30):  # 13 and 30 lap a ring of depth 8
        for _ in range(burst):
            pub.publish(M.UInt8MultiArray(data=rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8)))
        a, b = both()
        assert [(s, bytes(p), w) for s, p, w in a] == [(s, bytes(p), w) for s, p, w in b]
        assert all(isinstance(p, memoryview) and p.readonly for _, p, _ in a)
        assert fast.dropped == slow.dropped
    assert fast.dropped > 0
    for s in (fast, slow):
        s.close()
    pub.close()


@needs_c
@pytest.mark.unit
def test_big_frames_and_rings_to_grow_keep_the_python_path(ctx):
    """Frames over SMALL_FRAME_BYTES or over the slot come back encoded, the ring untouched; the
    publisher then writes them the Python way (growth, streaming copies, loans) as before."""
    pub = Publisher(ctx, "/big", M.UInt8MultiArray, publisher_id="w", depth=4, capacity=4096)
    sub = Subscriber(ctx, "/big", M.UInt8MultiArray, queue_size=16)
    ring = pub.ring
    for size in (5000, pubsub.SMALL_FRAME_BYTES + 1):
        msg = M.UInt8MultiArray(data=np.full(size, 7, np.uint8))
        got = pubsub._ring_publish(msg, ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, 1,
                                   pubsub.SMALL_FRAME_BYTES)
        assert isinstance(got, codec.Encoded) and ring.head == 0
    sizes = [8, 5000, 200_000, 16]
    for size in sizes:
        pub.publish(M.UInt8MultiArray(data=np.full(size, size % 251, np.uint8)))
    got = sub.take()
    assert [m.data.size for m in got] == sizes
    assert all((m.data == size % 251).all() for m, size in zip(got, sizes))
    sub.close()
    pub.close()


@needs_c
@pytest.mark.unit
def test_a_pinned_slot_is_never_written_by_the_c_path(ctx):
    """A loaning reader's pin on the slot the next message would retire: the C path restores the
    slot's seq and leaves the message to the Python path, which writes it elsewhere."""
    pub = Publisher(ctx, "/pin", M.Int64, publisher_id="w", depth=4)
    sub = Subscriber(ctx, "/pin", M.Int64, queue_size=16)
    for i in range(4):
        pub.publish(M.Int64(data=i))
    ring = pub.ring
    slot = ring.slot_of(0)  # message 4 retires message 0
    assert slot is not None
    before = bytes(ring.view[ring.slot_index(slot) * 8 : ring.slot_index(slot) * 8 + 64])
    ring.q[R._PIN_IDX + 3] = slot + 1  # as a loaning reader pins it
    got = pubsub._ring_publish(M.Int64(data=4), ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, 5,
                               pubsub.SMALL_FRAME_BYTES)
    assert isinstance(got, codec.Encoded)
    assert bytes(ring.view[ring.slot_index(slot) * 8 : ring.slot_index(slot) * 8 + 64]) == before
    assert pub.publish(M.Int64(data=4)) == 4
    assert ring.slot_of(4) != slot
    assert bytes(ring.view[ring.slot_index(slot) * 8 : ring.slot_index(slot) * 8 + 64]) == before
    assert ring.q[ring.slot_index(slot)] == 2  # still message 0, complete, for its loaning reader
    ring.q[R._PIN_IDX + 3] = 0
    assert [m.data for m in sub.take()] == [1, 2, 3, 4]  # message 4 retired message 0 (depth 4)
    sub.close()
    pub.close()


@needs_c
@pytest.mark.unit
@pytest.mark.parametrize("damage", ["slot-out-of-range", "head-past-limit", "length-past-capacity", "map-slot-on-read"])
def test_damaged_ring_words_are_left_to_the_python_path(ctx, damage):
    """Words of the segment another process may have scribbled on: the C path never reads or
    writes outside the mapping for them; it leaves the message to the Python path, which decides
    as it always did (another slot, or RingCorrupt and the ring dropped by the subscriber)."""
    pub = Publisher(ctx, "/damage", M.Int64, publisher_id="w", depth=4)
    sub = Subscriber(ctx, "/damage", M.Int64, queue_size=16)
    ring = pub.ring
    pub.publish(M.Int64(data=0))
    args = (ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity)
    if damage == "slot-out-of-range":
        ring.q[R._MAP_IDX + 1] = (R._EMPTY << 16) | 0xFFFF  # the entry message 1 retires
        assert isinstance(pubsub._ring_publish(M.Int64(data=1), *args, 1, pubsub.SMALL_FRAME_BYTES), codec.Encoded)
        assert pub.publish(M.Int64(data=1)) == 1  # Ring.begin claims any free slot
        assert [m.data for m in sub.take()] == [0, 1]
    elif damage == "head-past-limit":
        ring.q[R._HEAD] = R._MAX_HEAD
        assert isinstance(pubsub._ring_publish(M.Int64(data=1), *args, 1, pubsub.SMALL_FRAME_BYTES), codec.Encoded)
        assert ring.q[R._HEAD] == R._MAX_HEAD
    elif damage == "length-past-capacity":
        idx = ring.slot_index(ring.slot_of(0))
        ring.q[idx + 1] = ring.capacity + 1  # seq stays complete: damage, not a write in progress
        assert sub.take() == []
        assert "w" not in sub.sources  # dropped by the Python path's RingCorrupt, as before
    else:
        pub.publish(M.Int64(data=1))
        ring.q[R._MAP_IDX + 1] = (1 << 16) | 0xFFFF  # message 1 said to live in slot 65535
        out: list = []
        cursor, lapped = pubsub._ring_take(*args, 0, 2, 16384, out, "w")
        assert (cursor, lapped, [bytes(p) for _, p, _ in out]) == (1, 0, [_python_frame(M.Int64(data=0))])
        assert [m.data for m in sub.take()] == [0]  # then RingCorrupt at message 1: the ring is dropped
        assert "w" not in sub.sources
    sub.close()
    pub.close()


@needs_c
@pytest.mark.unit
def test_a_small_message_costs_few_python_calls_each_way(ctx):
    """The cause of the small-message throughput gap (issue 34): about 15 Python calls per publish
    (encode, claim, fences, write, commit, wake) and 5 per message taken. Now a publish is itself
    plus the wake-up check, and a batch of 16 messages is taken in a handful of calls in all."""
    from emos.transport.waker import Waker

    waker = Waker(ctx, spin_us=100)
    sub = Subscriber(ctx, "/calls", M.UInt8MultiArray, waker=waker, queue_size=64)
    pub = Publisher(ctx, "/calls", M.UInt8MultiArray, publisher_id="w", depth=16)
    waker.drain()  # the announcement: the subscriber finds the ring on its next take
    msg = M.UInt8MultiArray(data=np.zeros(8, np.uint8))
    for _ in range(3):
        pub.publish(msg)
    sub.take_raw()
    # The fewest over a few tries: a machine stalled past the subscriber's periodic rescan
    # (RESCAN_EVERY_NS) would add a directory scan to one of them.
    publish_calls = min(python_calls(pub.publish, msg) for _ in range(5))
    sub.take_raw()
    take_calls = 1 << 30
    for _ in range(3):
        for _ in range(16):
            pub.publish(msg)
        batch: list = []
        take_calls = min(take_calls, python_calls(lambda: batch.extend(sub.take_raw())))  # noqa: B023 - called at once
        assert len(batch) == 16
    assert publish_calls <= 2, f"a small publish entered {publish_calls} Python functions"
    assert take_calls <= 8, f"taking 16 small messages entered {take_calls} Python functions"
    sub.close()
    pub.close()
    waker.close()


# ------------------------------------------------------------------- a writer SIGKILLed mid-write
def _writer(ctx_dir: str, run_id: str, sizes: list[int], ready) -> None:
    ctx = RunContext(run_id, Path(ctx_dir), owner=False)
    pub = Publisher(ctx, "/small", M.UInt8MultiArray, publisher_id="writer", depth=4)
    rng = np.random.default_rng(os.getpid())
    ready.set()
    seq = 0
    while True:
        payload = rng.integers(0, 256, sizes[seq % len(sizes)], dtype=np.uint8)
        dim = M.MultiArrayDimension(label=f"{seq}:{zlib.crc32(payload.data)}", size=payload.size, stride=payload.size)
        pub.publish(M.UInt8MultiArray(layout=M.MultiArrayLayout(dim=[dim]), data=payload))
        seq += 1


def _check(msgs, last: int) -> int:
    for m in msgs:
        seq, crc = m.layout.dim[0].label.split(":")
        assert zlib.crc32(m.data.data) == int(crc), f"torn message {seq}"
        assert int(seq) > last, f"message {seq} after {last}"
        last = int(seq)
    return last


@needs_c
@pytest.mark.process
def test_no_torn_small_message_under_a_writer_sigkilled_at_random_times(ctx):
    """A writer publishing small messages flat out (the C path, depth 4, so readers are lapped
    too), SIGKILLed at random moments: every message read is intact and in order, before and
    after the kill, and a restarted writer goes on on the same ring."""
    fork = mp.get_context("fork")
    rnd = random.Random(11)
    sub = Subscriber(ctx, "/small", M.UInt8MultiArray, queue_size=8)
    last = -1
    for _ in range(6):
        ready = fork.Event()
        proc = fork.Process(target=_writer, args=(str(ctx.run_dir), ctx.run_id, [8, 100, 1000, 12000], ready))
        proc.start()
        try:
            assert ready.wait(30)
            for _ in range(rnd.randrange(5, 400)):
                got = sub.take()
                if got:
                    last = max(last, _check(got, -1))
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.join()
        _check(sub.take(), -1)
        ring = sub.sources["writer"].ring
        status, payload, _ = ring.read(ring.head)  # the message being written when it died
        assert status in (R.NOT_READY, R.LAPPED, R.OK)
        if status == R.OK:
            _check([M.decode(M.UInt8MultiArray, payload)], -1)
    assert last > 0
    sub.close()
