"""Damaged rings of our own (a crashed or buggy writer, a scribbled header): subscribers drop
them and keep delivering, readers never raise, restarted writers start a fresh generation."""
import logging

import numpy as np
import pytest

from emos import msgs as M
from emos.transport import ring as R
from emos.transport.context import SHM_DIR
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker

pytestmark = pytest.mark.unit


def _scribble(ring: R.Ring, how: str) -> None:
    q = np.frombuffer(ring.mm, dtype=np.uint64)
    n = ring.head - 1
    if how == "map-slot":  # the newest message lives in slot 0xFFFF
        q[R._MAP_IDX + n % ring.depth] = (n << 16) | 0xFFFF
    elif how == "length":  # the newest message is longer than a slot
        q[ring.slot_index(ring.slot_of(n)) + 1] = ring.capacity + 4096
    elif how == "sequence":  # a slot's sequence number from nowhere
        q[ring.slot_index(ring.slot_of(n))] = 12345
    elif how == "map-empty":
        q[R._MAP_IDX + n % ring.depth] = (R._EMPTY << 16) | (n % ring.depth)
    elif how == "magic":
        q[R._MAGIC] = 0xDEADBEEF
    elif how == "depth":
        q[R._GEOM] = (ring.generation << 32) | 0xFFFF
    elif how == "stride":
        q[R._STRIDE] = 1 << 40
    elif how == "head":
        q[R._FIRST] = ring.head + 5
    elif how == "moved-back":
        q[R._MOVED_PID] = (1 << 32) | 0  # harmless: moved_to 0 means "not moved"
        q[R._GEOM] = (3 << 32) | ring.depth  # but the header now claims generation 3
    else:
        raise ValueError(how)


@pytest.mark.parametrize("how", ["map-slot", "length"])
@pytest.mark.parametrize("read", ["take", "latest"])
def test_a_ring_damaged_while_read_is_dropped_and_other_publishers_keep_delivering(ctx, caplog, how, read):
    good = Publisher(ctx, "/t", M.String, publisher_id="good")
    bad = Publisher(ctx, "/t", M.String, publisher_id="bad")
    waker = Waker(ctx)
    sub = Subscriber(ctx, "/t", M.String, waker=waker)
    try:
        bad.publish(M.String(data="x" * 100))
        _scribble(bad.ring, how)
        for i in range(3):
            good.publish(M.String(data=f"good {i}"))
            got = sub.take() if read == "take" else [sub.latest()]
            assert [m.data for m in got] == [f"good {i}"]
        assert sub.publishers() == ["good"]
        warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert any("topic /t" in w and bad.ring.name in w for w in warnings), warnings
        assert sum(bad.ring.name in w for w in warnings) == 1  # rate-limited, not once per read
    finally:
        sub.close()
        waker.close()
        good.close()
        bad.close()


@pytest.mark.parametrize("how", ["magic", "depth", "stride", "head", "moved-back"])
def test_a_ring_with_an_inconsistent_header_is_never_attached(ctx, caplog, how):
    bad = Publisher(ctx, "/t", M.Int64, publisher_id="bad")
    bad.publish(M.Int64(data=1))
    _scribble(bad.ring, how)
    good = Publisher(ctx, "/t", M.Int64, publisher_id="good")
    sub = Subscriber(ctx, "/t", M.Int64, transient_local=True)
    try:
        good.publish(M.Int64(data=2))
        assert [m.data for m in sub.take()] == [2]
        assert sub.publishers() == ["good"]
        assert bad.ring.name in caplog.text
    finally:
        sub.close()
        good.close()
        bad.close()


def test_an_undecodable_message_is_skipped_and_counted(ctx, caplog):
    pub = Publisher(ctx, "/t", M.String, publisher_id="p")
    sub = Subscriber(ctx, "/t", M.String)
    try:
        pub.ring.write(b"\xff" * 40)  # a frame no String decodes from
        pub.publish(M.String(data="fine"))
        assert [m.data for m in sub.take()] == ["fine"]
        assert sub.undecodable == 1 and "does not decode" in caplog.text
    finally:
        sub.close()
        pub.close()


@pytest.mark.parametrize("how", ["map-slot", "length", "sequence", "map-empty", "magic", "depth", "stride", "head"])
def test_a_restarted_writer_replaces_its_damaged_ring_and_subscribers_follow(ctx, how):
    """Defect 7: the restarted writer used to reopen the broken generation (or fail to create g0)."""
    waker = Waker(ctx)
    sub = Subscriber(ctx, "/cam", M.String, waker=waker)
    pub = Publisher(ctx, "/cam", M.String, publisher_id="cam")
    try:
        for i in range(3):
            pub.publish(M.String(data=f"before {i}"))
        waker.drain()  # as a node does before it reads: counts the publisher's announcement
        assert len(sub.take()) == 3
        old = pub.ring.name
        _scribble(pub.ring, how)
        pub.close()  # the writer dies; a named publisher's ring stays for its restart
        pub = Publisher(ctx, "/cam", M.String, publisher_id="cam")
        assert pub.ring.name != old and pub.ring.generation == 1
        assert not (SHM_DIR / old).exists()
        for i in range(3):
            pub.publish(M.String(data=f"after {i}"))
        waker.drain()
        assert [m.data for m in sub.take()] == [f"after {i}" for i in range(3)]
        pub.publish(M.String(data="latest"))
        assert sub.latest().data == "latest"
    finally:
        sub.close()
        waker.close()
        pub.close()


@pytest.mark.parametrize("stop_after", ["begin", "seq", "map"])
def test_a_writer_killed_anywhere_in_a_write_leaves_a_ring_it_reopens(ctx, stop_after):
    """The restart check accepts every state a killed writer leaves; only real damage counts."""
    pub = Publisher(ctx, "/t", M.Int64, publisher_id="w", depth=4)
    sub = Subscriber(ctx, "/t", M.Int64, transient_local=True, queue_size=10)
    try:
        for i in range(6):
            pub.publish(M.Int64(data=i))
        ring = pub.ring
        n, buf = ring.begin(8)  # message 6, written up to where the writer was killed
        buf.release()
        q, slot = ring.q, ring._pending_slot
        if stop_after in ("seq", "map"):
            q[ring.slot_index(slot)] = 2 * n + 2
        if stop_after == "map":
            q[R._MAP_IDX + n % ring.depth] = (n << 16) | slot
        assert ring.damage() is None
        name = ring.name
        pub.close()
        pub = Publisher(ctx, "/t", M.Int64, publisher_id="w", depth=4)
        assert pub.ring.name == name
        pub.publish(M.Int64(data=60))
        assert [m.data for m in sub.take()][-1] == 60
    finally:
        sub.close()
        pub.close()
