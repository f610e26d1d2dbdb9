"""Long writes (issue 34, item 1): a publisher announces a long copy and wakes lingering readers
as it starts; a lingering reader keeps spinning while the copy runs instead of parking."""
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.transport.pubsub import ANNOUNCE_BYTES, Publisher, Subscriber
from emos.transport.waker import MAX_BUSY_US, PARKED, SPINNING, Waker

pytestmark = pytest.mark.unit


def _small(pub):
    pub.publish(M.UInt8MultiArray(data=np.zeros(8, np.uint8)))


def test_a_long_write_wakes_lingering_foreground_readers_as_it_starts_and_only_them(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam", capacity=1 << 20)  # no growth (which announces)
    lingering, background, no_spin = Waker(ctx, spin_us=100), Waker(ctx, spin_us=100, background=True), Waker(ctx, spin_us=0)
    subs = [Subscriber(ctx, "/cam", M.UInt8MultiArray, waker=w) for w in (lingering, background, no_spin)]
    _small(pub)  # the publisher learns of the subscribers
    for w in (lingering, background, no_spin):
        w.drain()
    with pub.loan(M.UInt8MultiArray, shape=(ANNOUNCE_BYTES,)) as msg:
        # Before the commit: the lingering reader is already awake and sees the write coming.
        assert lingering.drain() == 1
        assert background.drain() == 0 and no_spin.drain() == 0
        assert subs[0].busy_until() > time.monotonic_ns() - int(1e9)
        msg.data[:] = 1
    assert all(s.busy_until() == 0 for s in subs)  # the commit clears the announcement
    # After the commit every parked reader is woken as before.
    assert lingering.drain() == 1 and background.drain() == 1 and no_spin.drain() == 1
    # A small message is not announced and wakes nobody early.
    _small(pub)
    assert subs[0].busy_until() == 0


class _Busy:
    """A source whose publisher is always in the middle of a write ending ``ahead_ns`` from now."""

    def __init__(self, ahead_ns):
        self.ahead_ns = ahead_ns

    def busy_until(self):
        return time.monotonic_ns() + self.ahead_ns if self.ahead_ns else 0


@pytest.mark.parametrize("ahead_ns, pokes", [(0, False), (5_000_000, True), (int(MAX_BUSY_US * 1000) * 4, False)],
                         ids=["no-write", "write-in-progress", "implausible-deadline"])
def test_a_lingering_reader_waits_for_an_announced_write_and_then_gives_the_loop_its_turn(ctx, ahead_ns, pokes):
    waker = Waker(ctx, spin_us=20)
    waker.watch(_Busy(ahead_ns))
    handled = []
    waker.serve(lambda: handled.append(1), lambda: False)
    assert handled == [1]
    # Still busy at its linger deadline: it pokes itself so the event loop calls it again at
    # once; with no (believable) write in progress it parks silently.
    assert (waker.drain() > 0) is pokes
    waker.close()


def test_a_dead_writers_announcement_is_ignored(ctx):
    pub = Publisher(ctx, "/cam", M.UInt8MultiArray, publisher_id="cam")
    waker = Waker(ctx, spin_us=20)
    sub = Subscriber(ctx, "/cam", M.UInt8MultiArray, waker=waker)
    pub.ring.begin(64)
    pub.ring.announce(time.monotonic_ns() - 1)  # what a writer killed mid-copy leaves once its deadline passed
    waker.drain()
    waker.serve(lambda: None, sub.has_news)
    assert waker.drain() == 0
    assert sub.take() == []


def test_a_reader_whose_linger_ends_while_messages_flow_comes_back_still_spinning(ctx):
    """At its linger deadline a reader gives the event loop its turn. While messages still flow
    it must not park: parking made the next message pay a full wake-up, on most messages at
    8 MiB (a round trip there outlasts the linger). It pokes itself and stays SPINNING, so
    publishers write no wake-up and the next serve() takes what they published meanwhile."""
    waker = Waker(ctx, spin_us=100_000)  # an idle gap of 100 ms would end the linger: no test load makes one
    last = [time.monotonic_ns()]
    handled = []

    def has_news() -> bool:  # a message every millisecond, as a stream of frames
        return time.monotonic_ns() - last[0] >= 1_000_000

    def handle() -> None:
        handled.append(1)
        last[0] = time.monotonic_ns()

    waker.serve(handle, has_news)
    assert len(handled) > 2
    assert waker._state[0] == SPINNING  # publishers still skip the FIFO...
    assert waker.drain() == 1  # ...and the event loop calls us again at once
    # Once messages stop, the reader parks after one idle spin window, as before.
    waker.serve(lambda: None, lambda: False)
    assert waker._state[0] == PARKED
    assert waker.drain() == 0
    waker.close()
