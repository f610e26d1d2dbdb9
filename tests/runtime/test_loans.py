"""Zero-copy reads: loaned messages are views into the ring that the writer never overwrites."""
import gc
import multiprocessing as mp
import os
import random
import signal
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from emos import msgs as M
from emos.transport import ring as R
from emos.transport.context import RunContext
from emos.transport.loans import LOAN_MIN_BYTES
from emos.transport.pubsub import Publisher, Subscriber

pytestmark = pytest.mark.process

BIG = 2 * LOAN_MIN_BYTES  # loaned, and well inside the ring's first slot size


def _frame(value: int, size: int = BIG) -> M.UInt8MultiArray:
    return M.UInt8MultiArray(data=np.full(size, value % 256, dtype=np.uint8))


def _pins(ring: R.Ring) -> list[int]:
    return ring.q[R._PIN_IDX : R._PIN_IDX + R.LOAN_ENTRIES].tolist()


def test_big_messages_arrive_as_read_only_views_of_the_ring_small_ones_as_read_only_copies(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam")
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray)
    pub.publish(_frame(7))
    pub.publish(_frame(8, size=64))
    (_, big, _), (_, small, _) = sub.take_raw()
    assert isinstance(big, np.ndarray) and isinstance(small, memoryview)
    msg = M.decode(M.UInt8MultiArray, big)
    # The array's bytes are the slot's bytes, in the subscriber's mapping: no copy was made.
    ring = sub.sources["cam"].ring
    start = (ring.slot_index(ring.slot_of(0)) << 3) + R.SLOT_HEADER
    ring_bytes = np.frombuffer(ring.mm, dtype=np.uint8, count=len(big), offset=start)
    assert np.shares_memory(msg.data, ring_bytes)
    assert (msg.data == 7).all()
    with pytest.raises(ValueError, match="read-only"):
        msg.data[0] = 1
    with pytest.raises(ValueError, match="read-only"):
        M.decode(M.UInt8MultiArray, small).data[0] = 1


def test_a_held_loan_survives_the_writer_lapping_the_ring_and_ends_with_its_last_view(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=3)
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray, queue_size=1)
    pub.publish(_frame(1))
    held = sub.take()[0].data  # only the array is kept: it alone keeps the loan
    pinned_slot = pub.ring.slot_of(0)
    assert pinned_slot + 1 in _pins(pub.ring)
    for i in range(2, 40):  # more than ten times round the ring
        pub.publish(_frame(i))
        sub.take()
        assert (held == 1).all(), f"loaned frame overwritten by message {i}"
    assert pinned_slot + 1 in _pins(pub.ring)
    del held
    gc.collect()
    assert pinned_slot + 1 not in _pins(pub.ring)
    # The writer reuses the slot now that nobody holds it.
    used = set()
    for i in range(40, 40 + pub.ring.physical_slots * 2):
        pub.publish(_frame(i))
        used.add(pub.ring.slot_of(pub.ring.head - 1))
    assert used  # the ring keeps working; which slots it picks is its business


def test_a_subscriber_out_of_loans_gets_copies_and_the_publisher_never_stalls(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=2)
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray, queue_size=10, loans=2)
    kept = []
    for i in range(6):
        pub.publish(_frame(i))
        kept.extend(sub.take_raw())
    kinds = [type(raw).__name__ for _, raw, _ in kept]
    assert kinds == ["ndarray", "ndarray", "memoryview", "memoryview", "memoryview", "memoryview"]
    assert [int(M.decode(M.UInt8MultiArray, raw).data[0]) for _, raw, _ in kept] == list(range(6))
    assert sum(1 for p in _pins(pub.ring) if p) == 2
    kept.clear()
    gc.collect()
    assert not any(_pins(pub.ring))
    pub.publish(_frame(9))
    assert isinstance(sub.take_raw()[0][1], np.ndarray)  # loans are available again


def test_loans_can_be_turned_off(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam")
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray, loans=0)
    pub.publish(_frame(3))
    (_, raw, _), = sub.take_raw()
    assert isinstance(raw, memoryview)
    assert not any(_pins(pub.ring))


def test_a_loan_outlives_its_subscriber_and_the_ring_growing(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=2)
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray)
    pub.publish(_frame(5))
    held = sub.latest().data
    first_ring = pub.ring
    pub.publish(_frame(6, size=BIG * 8))  # grows: a new segment, the old one unlinked
    assert pub.ring is not first_ring
    got = sub.take()
    assert [int(m.data[0]) for m in got] == [6]
    sub.close()
    assert (held == 5).all()
    del held, got
    gc.collect()


def test_entries_of_a_sigkilled_reader_are_taken_over(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam")
    pub.publish(_frame(1))
    fork = mp.get_context("fork")
    ready = fork.Event()

    def reader() -> None:
        s = Subscriber(ctx, "/cam", M.UInt8MultiArray, loans=R.LOAN_ENTRIES, transient_local=True)
        _ = s.take()  # holds a loan on message 0 until it dies
        ready.set()
        time.sleep(60)

    proc = fork.Process(target=reader)
    proc.start()
    try:
        assert ready.wait(10)
        owners = pub.ring.q[R._PIN_OWNER_IDX : R._PIN_OWNER_IDX + R.LOAN_ENTRIES].tolist()
        assert owners == [proc.pid] * R.LOAN_ENTRIES
        assert any(_pins(pub.ring))
        # While it lives, nobody else gets an entry: they read copies.
        live = Subscriber(ctx, "/cam", M.UInt8MultiArray)
        assert live.sources["cam"].loans.entries == []
        live.close()
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
    for i in range(2, 30):  # its pin keeps one slot out of the way; the writer goes on
        pub.publish(_frame(i))
    late = Subscriber(ctx, "/cam", M.UInt8MultiArray)
    assert len(late.sources["cam"].loans.entries) == 2
    pub.publish(_frame(99))
    (_, raw, _), = late.take_raw()
    assert isinstance(raw, np.ndarray) and M.decode(M.UInt8MultiArray, raw).data[0] == 99
    late.close()


def _crc_writer(ctx_dir: str, run_id: str, depth: int, ready) -> None:
    ctx = RunContext(run_id, Path(ctx_dir), owner=False)
    pub = Publisher(ctx, "/stress", M.UInt8MultiArray, publisher_id="w", depth=depth)
    rng = np.random.default_rng(os.getpid())
    ready.set()
    seq = 0
    while True:
        payload = rng.integers(0, 256, BIG + (seq % 7) * 4096, dtype=np.uint8)
        dim = M.MultiArrayDimension(label=f"{seq}:{zlib.crc32(payload.data)}", size=payload.size, stride=payload.size)
        pub.publish(M.UInt8MultiArray(layout=M.MultiArrayLayout(dim=[dim]), data=payload))
        seq += 1


def _intact(msg: M.UInt8MultiArray) -> bool:
    _, crc = msg.layout.dim[0].label.split(":")
    return zlib.crc32(msg.data.data) == int(crc)


@pytest.mark.parametrize("depth", [2, 5])
def test_loans_held_for_random_times_are_never_overwritten_by_a_writer_flat_out(ctx, depth):
    """Each message is checked when it arrives and again just before its loan ends: the writer
    (another process, publishing as fast as it can) must never have written into it meanwhile."""
    fork = mp.get_context("fork")
    ready = fork.Event()
    proc = fork.Process(target=_crc_writer, args=(str(ctx.run_dir), ctx.run_id, depth, ready))
    proc.start()
    rnd = random.Random(1234)
    held: list[M.UInt8MultiArray] = []
    checked = loaned = 0
    try:
        assert ready.wait(10)
        sub = Subscriber(ctx, "/stress", M.UInt8MultiArray, queue_size=4, loans=2, transient_local=True)
        end = time.monotonic() + 2.5
        while time.monotonic() < end:
            for _, raw, _ in sub.take_raw():
                msg = M.decode(M.UInt8MultiArray, raw)
                assert _intact(msg), "torn on arrival"
                loaned += isinstance(raw, np.ndarray)
                held.append(msg)
            # Let go of a random subset, re-checking each before it goes.
            rnd.shuffle(held)
            keep = rnd.randint(0, min(3, len(held)))
            for msg in held[keep:]:
                assert _intact(msg), "overwritten while loaned"
                checked += 1
            del held[keep:]
            time.sleep(rnd.choice([0, 0, 0.0005, 0.002]))
        for msg in held:
            assert _intact(msg), "overwritten while loaned"
        sub.close()
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
    assert checked > 50 and loaned > 50, (checked, loaned)
