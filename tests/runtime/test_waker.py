"""Wake-ups: spin, then park. Publishers skip the FIFO of a spinning subscriber, and a message
published while the subscriber parks is never left unannounced."""
import threading
import time

import pytest

from emos import msgs as M
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import PARKED, SPINNING, Waker

pytestmark = pytest.mark.unit


def _pair(ctx, spin_us: float):
    waker = Waker(ctx, spin_us=spin_us)
    sub = Subscriber(ctx, "/w", M.Int64, waker=waker)
    pub = Publisher(ctx, "/w", M.Int64, publisher_id="p")
    assert waker.drain() > 0  # the publisher announced itself...
    assert sub.take() == []  # ...and the next read finds its ring
    return waker, sub, pub


def test_a_parked_subscriber_is_woken_through_its_fifo(ctx):
    waker, sub, pub = _pair(ctx, spin_us=0)
    assert not sub.has_news()
    pub.publish(M.Int64(data=1))
    assert sub.has_news()
    assert waker.drain() == 1
    assert [m.data for m in sub.take()] == [1]
    assert not sub.has_news()
    waker.close()


def test_a_spinning_subscriber_gets_messages_without_any_fifo_write(ctx):
    waker, sub, pub = _pair(ctx, spin_us=300_000)
    got: list[int] = []

    def publish_later() -> None:
        time.sleep(0.02)
        for i in range(3):
            pub.publish(M.Int64(data=i))

    thread = threading.Thread(target=publish_later)
    thread.start()
    started = time.monotonic()
    waker.serve(lambda: got.extend(m.data for m in sub.take()), sub.has_news)
    thread.join()
    assert got == [0, 1, 2]
    assert time.monotonic() - started < 5
    assert waker.drain() == 0  # every publish saw the subscriber spinning and skipped the FIFO
    assert waker._state[0] == PARKED
    waker.close()


def test_a_message_published_while_the_subscriber_parks_wakes_it_later(ctx):
    """The race the park protocol closes: the publisher saw SPINNING (so wrote nothing to the
    FIFO), but the spin had already given up. The look after parking must catch the message."""
    waker, sub, pub = _pair(ctx, spin_us=500)
    published = []

    def has_news() -> bool:
        if waker._state[0] == SPINNING:
            if not published:
                published.append(pub.publish(M.Int64(data=7)))  # seen as spinning: no FIFO write
            return False  # ...and the spin misses it, as a spin that just timed out would
        return sub.has_news()

    waker.serve(lambda: None, has_news)
    assert published
    assert waker.drain() == 1  # the park found the message and woke us
    assert [m.data for m in sub.take()] == [7]
    waker.close()


def test_spin_must_not_be_negative(ctx):
    import pytest

    with pytest.raises(ValueError, match="spin_us must be >= 0"):
        Waker(ctx, spin_us=-1)


def test_background_readers_are_woken_after_the_others(ctx, monkeypatch):
    """The Monitor and observers mark their token; a publisher wakes the robot's components first
    (on a machine with few cores the first woken takes the free core)."""
    import emos.transport.waker as W

    background = Waker(ctx, background=True)  # registered first: insertion order alone would wake it first
    foreground = [Waker(ctx) for _ in range(2)]
    assert background.token & W.BACKGROUND_BIT and not any(w.token & W.BACKGROUND_BIT for w in foreground)
    subs = [Subscriber(ctx, "/w", M.Int64, waker=w) for w in (background, *foreground)]
    pub = Publisher(ctx, "/w", M.Int64, publisher_id="p")
    for w, s in zip((background, *foreground), subs):
        w.drain()
        assert s.take() == []
    fifo_of = {pub.sender.fds[w.token]: w for w in (background, *foreground)}
    written: list = []
    real_write = W.os.write
    monkeypatch.setattr(W.os, "write", lambda fd, data: (written.append(fifo_of.get(fd)), real_write(fd, data))[1])
    pub.publish(M.Int64(data=7))
    assert written[-1] is background and set(written[:-1]) == set(foreground)
    for w, s in zip((background, *foreground), subs):
        assert w.drain() == 1 and [m.data for m in s.take()] == [7]
        w.close()
