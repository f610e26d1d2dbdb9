"""Recent-slot reuse (issue 34, 8 MiB between components): a volatile topic's publisher writes a
big message into the slot of the message before last when every reader has read it, so a
ping-pong cycles two slots of each ring instead of ``depth`` (cache- and TLB-friendly), while a
reader that lags, or one the writer cannot track, keeps the ring's whole depth of history; the
seqlock makes an overwritten message LAPPED, never torn (also under a SIGKILLed writer)."""
import multiprocessing as mp
import os
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emos import msgs as M
from emos.transport import ring as R
from emos.transport import ring_check
from emos.transport.context import SHM_DIR, RunContext
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker
from tests.ipc_loan.torn import sigkill_writer_and_check

pytestmark = pytest.mark.usefixtures("ring_path")  # the C calls and the Python path alike

BIG = R.RECENT_MIN_BYTES + 40
DEPTH = 10


def _payload(seq: int, size: int = BIG) -> np.ndarray:
    data = np.full(size, seq % 251, np.uint8)
    data[:8] = np.frombuffer(seq.to_bytes(8, "little"), np.uint8)
    return data


def _seq(msg: M.UInt8MultiArray) -> int:
    return int.from_bytes(bytes(msg.data[:8]), "little")


def _ping_pong_slots(ctx: RunContext, reuse: bool, tracked: bool = True, size: int = BIG, count: int = 3 * DEPTH) -> tuple[set[int], Subscriber, Publisher, Waker | None]:
    """Publish ``count`` messages, the subscriber taking each at once (a ping-pong's pace);
    the physical slots the messages after the first ``DEPTH`` went to."""
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=DEPTH, reuse_recent=reuse)
    waker = Waker(ctx) if tracked else None
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray, waker=waker, queue_size=DEPTH)
    slots = set()
    for seq in range(count):
        n = pub.publish(M.UInt8MultiArray(data=_payload(seq, size)))
        if waker is not None:
            waker.drain()  # a grown ring announces itself
        got = sub.take()
        assert [_seq(m) for m in got] == [seq]
        del got  # ends the loan, as a component's next message does
        if seq >= DEPTH:
            slots.add(pub.ring.slot_of(n))
    return slots, sub, pub, waker


def _close(sub: Subscriber, pub: Publisher, waker: Waker | None) -> None:
    sub.close()
    pub.close()
    if waker is not None:
        waker.close()


@pytest.mark.unit
def test_a_ping_pong_of_big_messages_cycles_two_slots_instead_of_depth(ctx):
    slots, *parts = _ping_pong_slots(ctx, reuse=True)
    assert len(slots) == 2  # round robin: DEPTH
    _close(*parts)


@pytest.mark.unit
def test_without_reuse_small_messages_or_an_untracked_reader_the_ring_goes_round(ctx):
    for kwargs, topic in (({"reuse": False}, "off"), ({"reuse": True, "size": R.RECENT_MIN_BYTES - 1024}, "small"),
                          ({"reuse": True, "tracked": False}, "untracked")):
        slots, sub, pub, waker = _ping_pong_slots(ctx, **kwargs)
        assert len(slots) == DEPTH, topic
        if topic == "untracked":
            assert pub.ring.untracked == 1
            sub.close()
            assert pub.ring.untracked == 0  # closing gives the count back
        _close(sub, pub, waker)
        for name in ctx.topic_segments("/cam"):
            os.unlink(SHM_DIR / name)  # the next case starts a fresh ring, not this one re-opened


@pytest.mark.unit
def test_a_reader_that_lags_keeps_the_whole_depth_of_history(ctx):
    _, sub, pub, waker = _ping_pong_slots(ctx, reuse=True, count=5)
    for seq in range(5, 5 + DEPTH):  # the reader does not read meanwhile
        pub.publish(M.UInt8MultiArray(data=_payload(seq)))
    got = sub.take()
    assert [_seq(m) for m in got] == list(range(5, 5 + DEPTH)) and sub.dropped == 0
    assert all((m.data[8:] == _seq(m) % 251).all() for m in got)
    del got
    _close(sub, pub, waker)


@pytest.mark.unit
def test_a_late_transient_local_reader_gets_the_newest_message_and_no_hole(ctx):
    _, sub, pub, waker = _ping_pong_slots(ctx, reuse=True)
    late = Subscriber(ctx, "/cam", M.UInt8MultiArray, queue_size=DEPTH, transient_local=True)
    got = late.take()
    assert got and _seq(got[-1]) == 3 * DEPTH - 1  # the newest is never overwritten
    assert all((m.data[8:] == _seq(m) % 251).all() for m in got) and late.undecodable == 0
    del got
    late.close()
    _close(sub, pub, waker)


@pytest.mark.unit
def test_a_ring_with_stale_map_entries_is_not_damaged_and_a_restart_carries_on(ctx):
    _, sub, pub, waker = _ping_pong_slots(ctx, reuse=True)
    assert ring_check.damage(pub.ring) is None
    head, generation = pub.ring.head, pub.ring.generation
    pub.close()  # a named publisher keeps its ring for its restart
    again = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=DEPTH, reuse_recent=True)
    assert (again.ring.generation, again.ring.head) == (generation, head)  # re-opened, not replaced as damaged
    # Back to round robin while the reader lags: every message lands in a slot no other kept one uses.
    for seq in range(head, head + DEPTH):
        again.publish(M.UInt8MultiArray(data=_payload(seq)))
    assert ring_check.damage(again.ring) is None
    got = sub.take()
    assert [_seq(m) for m in got] == list(range(head, head + DEPTH))
    assert all((m.data[8:] == _seq(m) % 251).all() for m in got)
    del got
    _close(sub, again, waker)


@pytest.mark.unit
def test_a_ring_grown_after_recent_writes_carries_no_hole(ctx):
    _, sub, pub, waker = _ping_pong_slots(ctx, reuse=True)
    generation = pub.ring.generation
    pub.publish(M.UInt8MultiArray(data=_payload(999, 4 * BIG)))  # grows the ring
    assert pub.ring.generation == generation + 1
    waker.drain()
    assert [_seq(m) for m in sub.take()] == [999] and sub.dropped == 0
    late = Subscriber(ctx, "/cam", M.UInt8MultiArray, queue_size=DEPTH, transient_local=True)
    got = late.take()
    assert got and _seq(got[-1]) == 999 and late.undecodable == 0
    del got
    late.close()
    _close(sub, pub, waker)


# -- SIGKILL: a writer killed in the middle of a recent-slot write leaves nothing torn ---------------
_RECENT_WRITES = mp.get_context("fork").Value("q", 0, lock=False)  # shared with the forked writer


def _recent_writer(run_dir: str, run_id: str, size: int, ready) -> None:
    """Publishes forever with recent-slot reuse, waiting (briefly) for the reader to catch up
    after each message so that most writes take the slot of the message before last."""
    ctx = RunContext(run_id, Path(run_dir), owner=False)
    pub = Publisher(ctx, "/stream", M.UInt8MultiArray, publisher_id="writer", depth=DEPTH, reuse_recent=True)
    payloads = [np.random.default_rng(i).integers(0, 256, size, dtype=np.uint8) for i in range(3)]
    crcs = [zlib.crc32(p.data) for p in payloads]
    ready.set()
    seq = 0
    while True:
        k = seq % 3
        head = pub.ring.head  # numbering goes on from an earlier example's writer (same run)
        before = pub.ring.slot_of(head - 2) if head >= 2 else None
        dim = M.MultiArrayDimension(label=f"{seq}:{crcs[k]}", size=size, stride=size)
        n = pub.publish(M.UInt8MultiArray(layout=M.MultiArrayLayout(dim=[dim]), data=payloads[k]))
        if before is not None and pub.ring.slot_of(n) == before:
            _RECENT_WRITES.value += 1
        seq += 1
        until = time.monotonic() + 0.01
        while time.monotonic() < until and not all(pub.ring.q[i] >= n + 1 for i in pub.ring._readers):
            pass


@pytest.mark.process
@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(size=st.sampled_from([R.RECENT_MIN_BYTES + 24, 2 * R.RECENT_MIN_BYTES + 8]), kill_after=st.floats(0.0, 0.05))
def test_no_torn_message_when_the_writer_is_sigkilled_mid_recent_slot_write(ctx, size, kill_after):
    _RECENT_WRITES.value = 0
    sigkill_writer_and_check(ctx, _recent_writer, size, kill_after, tracked=True, armed=lambda: _RECENT_WRITES.value > 0)
    assert _RECENT_WRITES.value > 0  # the writer did reuse recent slots while being read


@pytest.mark.unit
def test_a_writer_killed_mid_recent_write_restarts_on_the_same_ring_twice(ctx):
    _, sub, pub, waker = _ping_pong_slots(ctx, reuse=True)
    ring = pub.ring
    n, buf = ring.begin(BIG, recent=True)  # a writer killed here: seq odd in the slot of n - 2
    buf.release()
    assert ring._pending_slot == ring.slot_of(n - 2)
    generation = ring.generation
    for restart in range(2):  # the second restart finds the first one's messages around the stale slot
        again = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", depth=DEPTH, reuse_recent=True)
        assert again.ring.generation == generation, f"restart {restart} replaced the ring as damaged"
        first = again.ring.head
        for seq in range(first, first + 3):
            again.publish(M.UInt8MultiArray(data=_payload(seq)))
        assert ring_check.damage(again.ring) is None
        got = sub.take()
        assert [_seq(m) for m in got] == list(range(first, first + 3))
        del got
        again.ring.close()  # killed again, between messages this time
        again.ring = None
        again.sender.close()
    pub.sender.close()  # the first writer is gone too (killed: its ring stays)
    pub.ring.close()
    pub.ring = None
    sub.close()
    waker.close()
