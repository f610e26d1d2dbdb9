"""Big messages through the rings in one C call each way (``_ccodec.ring_write`` for the
publisher, ``ring_loan`` for a loaning subscriber; docs/ipc.md, "Big messages: one C call each
way").

They must do what ring.py's Python path does (the same slots, recent-slot reuse included, the
codec's frames, the same loans and statuses), keep its distrust of the segment, and leave what
they do not handle (a pinned slot, a damaged word, an array that is not contiguous) to the
Python path with the ring untouched. Their point is fewer interpreter steps around a big copy:
that is counted in Python calls, not in time. The torn-read tests under a SIGKILLed writer run on
both paths through the ``ring_path`` fixture (test_recent_slots.py, test_loan_sigkill.py).
"""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from emos.msgs import codec
from emos.transport import loans, pubsub
from emos.transport import ring as R
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker
from tests.python_calls import python_calls

pytestmark = [pytest.mark.unit,
              pytest.mark.skipif(pubsub._ring_write is None or loans._ring_loan is None,
                                 reason="the C codec is not built (no compiler at install, or EMOS_CODEC=python)")]

BIG = R.RECENT_MIN_BYTES + 24  # recent-slot reuse applies from RECENT_MIN_BYTES


def _frame(ring: R.Ring, n: int) -> bytes:
    status, payload, _ = ring.read(n)
    assert status == R.OK and payload is not None
    return bytes(payload)


def _geometry(ring: R.Ring) -> tuple:
    return ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity


def _messages(rng: np.random.Generator) -> list:
    """Big frames of several shapes: one array, several arrays, a frame past the recent-slot size."""
    out = []
    for size in (200_000, 921_600, BIG, BIG + 3, 300_001):
        out.append(M.UInt8MultiArray(data=rng.integers(0, 256, size, dtype=np.uint8)))
    cloud = rng.integers(0, 256, 640_003, dtype=np.uint8)
    out.append(M.PointCloud2(height=1, width=3, point_step=4, row_step=12, data=cloud))
    out.append(M.Image.from_numpy(rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)))
    return out


@pytest.mark.parametrize("reuse_recent", [False, True])
def test_big_frames_go_to_the_same_slots_as_the_python_path_and_are_the_codecs_frames(ctx, monkeypatch, reuse_recent):
    """The same messages through two publishers, one per path, each read at once by a tracked
    reader (the pace at which recent slots are reused) and, every third message, by a reader that
    lags: the same message numbers and slots, and the C path's frames are the codec's, bytes for
    bytes (its padding zeroed); the Python path's decode to the same messages."""
    rng = np.random.default_rng(11)
    msgs = _messages(rng) * 3
    slots: dict[str, list[int]] = {}
    for path in ("c", "python"):
        if path == "python":
            monkeypatch.setattr(pubsub, "_ring_write", None)
        waker = Waker(ctx)
        pub = Publisher(ctx, f"/{path}", M.UInt8MultiArray, publisher_id="w", depth=6, reuse_recent=reuse_recent, capacity=4 << 20)
        sub = Subscriber(ctx, f"/{path}", M.UInt8MultiArray, waker=waker, queue_size=8)
        late_waker = Waker(ctx)
        lagging = Subscriber(ctx, f"/{path}", M.UInt8MultiArray, waker=late_waker, queue_size=8)
        waker.drain()
        slots[path] = []
        sent = [m for m in msgs if isinstance(m, M.UInt8MultiArray)]
        for i, msg in enumerate(sent):
            n = pub.publish(msg)
            assert n == i
            slots[path].append(pub.ring.slot_of(n))
            if path == "c":
                assert _frame(pub.ring, n) == codec.encode_python(msg).to_bytes(), f"message {n}"
            [got] = sub.take()
            assert np.array_equal(got.data, msg.data)
            del got
            if i % 3 == 2:  # the lagging reader: whatever it still finds is whole, the newest last
                late = lagging.take()
                assert late and np.array_equal(late[-1].data, msg.data)
                assert all(any(np.array_equal(m.data, s.data) for s in sent[i - 2 : i + 1]) for m in late)
                del late
        lagging.close()  # the prompt reader alone: with reuse_recent, big messages take recent slots
        for k in range(8):
            big = M.UInt8MultiArray(data=np.full(BIG, k, np.uint8))
            slots[path].append(pub.ring.slot_of(pub.publish(big)))
            del sub.take()[:]
        for part in (sub, pub, waker, late_waker):
            part.close()
    assert slots["c"] == slots["python"]
    assert len(set(slots["c"][-6:])) == (2 if reuse_recent else 6), slots["c"]  # recent slots, or round robin


def test_every_big_message_type_arrives_intact_through_the_c_path(ctx):
    rng = np.random.default_rng(5)
    for k, msg in enumerate(_messages(rng)):
        cls = type(msg)
        pub = Publisher(ctx, f"/t{k}", cls, publisher_id="w", depth=3)
        sub = Subscriber(ctx, f"/t{k}", cls, queue_size=4)
        ring = pub.ring
        pub.publish(msg)  # grows the ring: the Python path
        ring = pub.ring
        n = pubsub._ring_write(codec.encode(msg), *_geometry(ring), 77, 0, codec.STREAM_MIN_BYTES)
        assert n == 1 and ring.head == 2 and ring.stamp_of(1) == 77
        assert _frame(ring, 1) == codec.encode_python(msg).to_bytes()
        got = sub.take()
        assert len(got) == 2 and codec.encode_python(got[1]).to_bytes() == codec.encode_python(msg).to_bytes()
        del got
        sub.close()
        pub.close()


def test_a_pinned_slot_is_left_to_the_python_path_with_the_ring_untouched(ctx):
    """A loaning reader pins the slot the next message would retire: ring_write restores its seq
    and returns None; the publisher then writes the message elsewhere, the loan's bytes intact."""
    pub = Publisher(ctx, "/pin", M.UInt8MultiArray, publisher_id="w", depth=3, capacity=1 << 20)
    sub = Subscriber(ctx, "/pin", M.UInt8MultiArray, queue_size=8)
    for i in range(3):
        pub.publish(M.UInt8MultiArray(data=np.full(500_000, i, np.uint8)))
    ring = pub.ring
    slot = ring.slot_of(0)  # message 3 retires message 0
    start = ring.slot_index(slot) * 8
    before = bytes(ring.view[start : start + R.SLOT_HEADER + 500_100])
    ring.q[R._PIN_IDX + 5] = slot + 1  # as a loaning reader pins it
    enc = codec.encode(M.UInt8MultiArray(data=np.full(500_000, 3, np.uint8)))
    assert pubsub._ring_write(enc, *_geometry(ring), 1, 0, codec.STREAM_MIN_BYTES) is None
    assert ring.head == 3 and bytes(ring.view[start : start + R.SLOT_HEADER + 500_100]) == before
    assert pub.publish(M.UInt8MultiArray(data=np.full(500_000, 3, np.uint8))) == 3
    assert ring.slot_of(3) != slot and bytes(ring.view[start : start + R.SLOT_HEADER + 500_100]) == before
    ring.q[R._PIN_IDX + 5] = 0
    assert [int(m.data[0]) for m in sub.take()] == [1, 2, 3]  # depth 3: message 0 retired
    sub.close()
    pub.close()


@pytest.mark.parametrize("damage", ["slot-out-of-range", "head-past-limit", "not-contiguous", "not-encoded"])
def test_damaged_words_and_odd_frames_are_left_to_the_python_path(ctx, damage):
    pub = Publisher(ctx, "/damage", M.UInt8MultiArray, publisher_id="w", depth=4, capacity=1 << 20)
    sub = Subscriber(ctx, "/damage", M.UInt8MultiArray, queue_size=8)
    ring = pub.ring
    data = np.arange(400_000, dtype=np.uint8)
    pub.publish(M.UInt8MultiArray(data=data))
    header = bytes(ring.view[: ring.data_offset])
    enc = codec.encode(M.UInt8MultiArray(data=data))
    if damage == "slot-out-of-range":
        ring.q[R._MAP_IDX + 1] = (R._EMPTY << 16) | 0xFFFF  # the entry message 1 retires
        header = bytes(ring.view[: ring.data_offset])
        assert pubsub._ring_write(enc, *_geometry(ring), 1, 0, codec.STREAM_MIN_BYTES) is None
        assert bytes(ring.view[: ring.data_offset]) == header
        assert pub.publish(M.UInt8MultiArray(data=data)) == 1  # Ring.begin claims any free slot
        assert len(sub.take()) == 2
    elif damage == "head-past-limit":
        ring.q[R._HEAD] = R._MAX_HEAD
        header = bytes(ring.view[: ring.data_offset])
        assert pubsub._ring_write(enc, *_geometry(ring), 1, 0, codec.STREAM_MIN_BYTES) is None
        assert bytes(ring.view[: ring.data_offset]) == header
    elif damage == "not-contiguous":
        odd = codec.Encoded(enc.meta, [np.arange(800_000, dtype=np.uint8)[::2]], 400_000)
        assert pubsub._ring_write(odd, *_geometry(ring), 1, 0, codec.STREAM_MIN_BYTES) is None
        assert bytes(ring.view[: ring.data_offset]) == header
    else:
        with pytest.raises(TypeError, match="codec.Encoded"):
            pubsub._ring_write(object(), *_geometry(ring), 1, 0, codec.STREAM_MIN_BYTES)
        assert bytes(ring.view[: ring.data_offset]) == header
    sub.close()
    pub.close()


def _loan_both(ring: R.Ring, n: int, entry: int):
    """``(C result, Python result)`` for loaning message ``n`` through pin ``entry``, each pin
    given back after."""
    fast = loans._ring_loan(*_geometry(ring), n, entry)
    if fast is not None and fast[0] == R.OK:
        fast = (fast[0], bytes(fast[1]), fast[2], fast[1].flags.writeable)
    ring.q[R._PIN_IDX + entry] = 0
    slow = ring.loan(n, entry)
    if slow[0] == R.OK:
        slow = (slow[0], bytes(slow[1]), slow[2], slow[1].flags.writeable)
    ring.q[R._PIN_IDX + entry] = 0
    return fast, slow


def test_ring_loan_gives_what_ring_loan_gives_for_every_status(ctx):
    pub = Publisher(ctx, "/loan", M.UInt8MultiArray, publisher_id="w", depth=3, capacity=1 << 20)
    for i in range(5):
        pub.publish(M.UInt8MultiArray(data=np.full(300_000, i, np.uint8)))
    ring = pub.ring
    for n in (2, 3, 4):  # held: OK, read-only views of the same bytes and stamps
        fast, slow = _loan_both(ring, n, 1)
        assert fast == slow and fast[0] == R.OK and fast[3] is False
    assert _loan_both(ring, 5, 1) == ((R.NOT_READY, None, 0), (R.NOT_READY, None, 0))  # not written yet
    assert _loan_both(ring, 0, 1) == ((R.LAPPED, None, 0), (R.LAPPED, None, 0))  # overwritten
    idx = ring.slot_index(ring.slot_of(4))
    ring.q[idx] = 2 * 4 + 1  # being rewritten after the map was read: LAPPED, the pin given back
    assert loans._ring_loan(*_geometry(ring), 4, 2) == (R.LAPPED, None, 0) and ring.q[R._PIN_IDX + 2] == 0
    ring.q[idx] = 2 * 4 + 2
    pub.close()


@pytest.mark.parametrize("damage", ["slot-out-of-range", "length-past-capacity", "entry-out-of-range"])
def test_a_damaged_loan_is_left_to_ring_loan_which_reports_it_and_no_pin_stays(ctx, damage):
    pub = Publisher(ctx, "/bad", M.UInt8MultiArray, publisher_id="w", depth=3, capacity=1 << 20)
    pub.publish(M.UInt8MultiArray(data=np.full(300_000, 9, np.uint8)))
    ring = pub.ring
    entry = 1
    if damage == "slot-out-of-range":
        ring.q[R._MAP_IDX + 0] = (0 << 16) | 0xFFFF
    elif damage == "length-past-capacity":
        ring.q[ring.slot_index(ring.slot_of(0)) + 1] = ring.capacity + 1
    else:
        entry = R.LOAN_ENTRIES
    assert loans._ring_loan(*_geometry(ring), 0, entry) is None
    assert not any(ring.q[R._PIN_IDX + e] for e in range(R.LOAN_ENTRIES))
    if damage != "entry-out-of-range":
        with pytest.raises(R.RingCorrupt):
            ring.loan(0, entry)
        assert ring.q[R._PIN_IDX + entry] == 0
    pub.close()


def test_a_loaned_view_keeps_the_mapping_and_its_pin_until_it_is_dropped(ctx):
    """As numpy.frombuffer's views: the ring may close under a loan; the bytes stay readable, and
    the loan book unpins the slot when the last reference goes."""
    pub = Publisher(ctx, "/keep", M.UInt8MultiArray, publisher_id="w", depth=3, capacity=1 << 20)
    sub = Subscriber(ctx, "/keep", M.UInt8MultiArray, queue_size=4)
    pub.publish(M.UInt8MultiArray(data=np.full(300_000, 42, np.uint8)))
    [msg] = sub.take()
    ring = pub.ring
    assert sum(1 for e in range(R.LOAN_ENTRIES) if ring.q[R._PIN_IDX + e]) == 1
    with pytest.raises(ValueError):
        msg.data[0] = 1  # read-only: other readers share these bytes
    pins = ring.pins()
    sub.close()
    pub.close()  # the publisher's mapping goes; the loan's own buffer export keeps the bytes
    assert int(msg.data.sum()) == 42 * 300_000
    del msg
    assert not any(pins.held(e) for e in range(R.LOAN_ENTRIES))
    pins.close()


def test_a_big_message_costs_few_python_calls_each_way(ctx, monkeypatch):
    """What the C calls are for: a big publish entered 22 Python functions (begin, claim,
    announce, write_into, commit, fences) and a loaned take 11; now 8 and 7 (9 allowed; the
    announcement, the wake-ups and the loan book's weak reference stay in Python).
    The Python path is counted too, so the test shows the difference it guards."""
    counts = {}
    for path in ("c", "python"):
        if path == "python":
            monkeypatch.setattr(pubsub, "_ring_write", None)
            monkeypatch.setattr(loans, "_ring_loan", None)
        waker = Waker(ctx, spin_us=100)
        sub = Subscriber(ctx, f"/calls_{path}", M.UInt8MultiArray, waker=waker, queue_size=8)
        pub = Publisher(ctx, f"/calls_{path}", M.UInt8MultiArray, publisher_id="w", depth=4, capacity=1 << 20)
        waker.drain()
        msg = M.UInt8MultiArray(data=np.zeros(921_600, np.uint8))
        for _ in range(2):
            pub.publish(msg)
            del sub.take_raw()[:]
        publish_calls = min(python_calls(pub.publish, msg) for _ in range(3))
        del sub.take_raw()[:]
        take_calls = 1 << 30
        for _ in range(3):
            pub.publish(msg)
            taken: list = []
            take_calls = min(take_calls, python_calls(lambda: taken.extend(sub.take_raw())))  # noqa: B023 - called at once
            assert len(taken) == 1
            taken.clear()  # ends the loan
        counts[path] = (publish_calls, take_calls)
        sub.close()
        pub.close()
        waker.close()
    assert counts["c"][0] <= 9, f"a big publish entered {counts['c'][0]} Python functions (Python path: {counts['python'][0]})"
    assert counts["c"][1] <= 9, f"a big take entered {counts['c'][1]} Python functions (Python path: {counts['python'][1]})"
    assert counts["python"][0] > counts["c"][0] + 5 and counts["python"][1] > counts["c"][1] + 2, counts
