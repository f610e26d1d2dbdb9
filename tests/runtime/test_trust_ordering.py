"""Memory order on weakly ordered CPUs, and no wake-up lost while publishers and subscribers start."""
import os
import select
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.transport import ring as R
from emos.transport.context import ENV_RUN_DIR, ENV_RUN_ID
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker

pytestmark = pytest.mark.process


_WATCHED: list = []  # [ring, message number] whose state each fence records


def _state() -> tuple | None:
    if not _WATCHED:
        return None
    ring, n = _WATCHED
    # Nothing is pinned, so message n goes to the slot of the message it retires, which the map
    # entry names until the commit's last step.
    idx = ring.slot_index(ring.q[R._MAP_IDX + n % ring.depth] & 0xFFFF)
    return (ring.q[idx], ring.q[idx + 1], ring.q[R._MAP_IDX + n % ring.depth] >> 16, ring.q[R._HEAD])


@pytest.fixture
def weak_cpu(monkeypatch):
    """Run the ring as on arm64, recording the watched ring's state at every fence."""
    calls: list = []
    monkeypatch.setattr(R, "WEAK_ORDERING", True)
    monkeypatch.setattr(R, "full_fence", lambda: calls.append(_state()))
    yield calls
    _WATCHED.clear()


def test_on_a_weakly_ordered_cpu_the_writer_fences_each_step_of_the_seqlock(ctx, weak_cpu):
    pub = Publisher(ctx, "/t", M.Int64, publisher_id="p", depth=4)
    try:
        ring = pub.ring
        for _ in range(5):  # wrap the ring once, so map entries hold older messages
            ring.write(b"x" * 8)
        n = ring.head
        _WATCHED[:] = [ring, n]
        weak_cpu.clear()
        ring.write(b"y" * 24)
        _WATCHED.clear()
        # (seq, length, message held by the map entry, head) at each fence, in program order:
        # claim (seq odd, before the payload), then payload+length before seq even, then seq
        # even before the map entry; head follows the map entry.
        assert weak_cpu == [
            (2 * n + 1, 8, n - 4, n),
            (2 * n + 1, 24, n - 4, n),
            (2 * n + 2, 24, n - 4, n),
        ]
        assert ring.q[R._MAP_IDX + n % 4] >> 16 == n and ring.head == n + 1
    finally:
        _WATCHED.clear()
        pub.close()


def test_on_a_weakly_ordered_cpu_the_reader_fences_around_its_copy(ctx, weak_cpu):
    pub = Publisher(ctx, "/t", M.Int64, publisher_id="p", depth=4)
    try:
        n = pub.ring.write(b"z" * 16)
        reader = R.Ring.attach(pub.ring.name)
        weak_cpu.clear()
        status, buf, _ = reader.read(n)
        # map entry | fence | seq | fence | length, payload | fence | seq again
        assert status == R.OK and bytes(buf) == b"z" * 16 and len(weak_cpu) == 3
        reader.close()
    finally:
        pub.close()


def test_a_publisher_that_appears_after_a_subscriber_is_read_from_its_first_message_even_if_the_clock_stepped_back(ctx, monkeypatch):
    """The start cursor came from comparing wall-clock stamps of two processes; a clock step
    back (NTP, a VM resumed) between subscribing and the publisher's start lost its first
    messages: the ping-pong that waited for a first reply forever."""
    waker = Waker(ctx)
    sub = Subscriber(ctx, "/t", M.Int64, waker=waker)
    real = time.time_ns
    monkeypatch.setattr(time, "time_ns", lambda: real() - 3600 * 10**9)
    pub = Publisher(ctx, "/t", M.Int64, publisher_id="p")
    try:
        pub.publish(M.Int64(data=1))  # published before the subscriber looked for rings
        monkeypatch.undo()
        assert waker.drain() >= 1  # it was announced and woken
        assert [m.data for m in sub.take()] == [1]
    finally:
        sub.close()
        waker.close()
        pub.close()


def test_a_subscriber_whose_listing_missed_a_ring_finds_it_when_the_ring_grows(ctx, monkeypatch):
    """A directory listing that runs while one name is created and another removed may return
    neither. The subscriber below misses the publisher's ring that way; the publisher's first
    big message then moves the ring to a new generation, and must make the subscriber look
    again: nothing else would wake it (the ping-pong bench hung so at sizes that grow rings)."""
    waker = Waker(ctx)
    sub = Subscriber(ctx, "/grows", M.UInt8MultiArray, waker=waker)
    pub = Publisher(ctx, "/grows", M.UInt8MultiArray, publisher_id="p")
    try:
        real_listdir = os.listdir
        with monkeypatch.context() as m:
            m.setattr(os, "listdir", lambda d: [n for n in real_listdir(d) if ".grows." not in n])
            waker.drain()  # the publisher's announcement...
            assert sub.take() == [] and sub.publishers() == []  # ...and a listing that missed it
        pub.publish(M.UInt8MultiArray(data=np.arange(200_000, dtype=np.uint8)))  # grows the ring
        assert pub.ring.generation == 1
        assert waker.drain() >= 1
        got = sub.take()
        assert len(got) == 1 and got[0].data.size == 200_000
    finally:
        sub.close()
        waker.close()
        pub.close()


ECHO = textwrap.dedent(
    """
    import select, sys, time
    from emos import msgs as M
    from emos.transport.context import current
    from emos.transport.pubsub import Publisher, Subscriber
    from emos.transport.waker import Waker

    ctx = current()
    for line in sys.stdin:
        listen, speak, spin = line.split()
        waker = Waker(ctx, spin_us=float(spin))
        sub = Subscriber(ctx, listen, M.UInt8MultiArray, waker=waker)
        pub = Publisher(ctx, speak, M.UInt8MultiArray, publisher_id="echo")
        print("ready", flush=True)
        got = []
        end = time.monotonic() + 10
        while not got and time.monotonic() < end:
            # Only a wake-up makes us look: a lost one shows up as "lost", not as a slow poll.
            if select.select([waker.fd], [], [], 0.5)[0]:
                waker.serve(lambda: got.extend(sub.take()), sub.has_news)
        if got:
            pub.publish(M.UInt8MultiArray(data=got[0].data))  # as big as the ping: grows the ring too
        print("done" if got else "lost", flush=True)
        sub.close(); pub.close(); waker.close()
    """
)


def _line(proc: subprocess.Popen, timeout: float = 15.0) -> str:
    if not select.select([proc.stdout], [], [], timeout)[0]:
        raise AssertionError(f"echo process silent for {timeout} s")
    return proc.stdout.readline().strip()


def test_starting_and_stopping_publisher_subscriber_pairs_never_loses_the_first_wake_up(ctx):
    """Like the ping-pong bench, many times over: the echo subscribes and says ready, we publish
    at once, and the first message must wake it. Odd rounds use fresh topics (rings created
    while the other side subscribes), even rounds reuse the same ones (rings re-opened); every
    third round's first message is too big for a new ring, which grows under the subscriber
    that is just finding it (the bench hung there about once in a hundred starts)."""
    env = {**os.environ, ENV_RUN_DIR: str(ctx.run_dir), ENV_RUN_ID: ctx.run_id}
    echo = subprocess.Popen([sys.executable, "-c", ECHO], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    rounds = 300
    try:
        for i in range(rounds):
            ping, pong = (f"/stress/{i}/ping", f"/stress/{i}/pong") if i % 2 else ("/stress/ping", "/stress/pong")
            spin = (0, 100)[i % 4 < 2]
            echo.stdin.write(f"{ping} {pong} {spin}\n")
            echo.stdin.flush()
            waker = Waker(ctx, spin_us=spin)  # set up while the echo sets up
            sub = Subscriber(ctx, pong, M.UInt8MultiArray, waker=waker)
            pub = None
            try:
                assert _line(echo) == "ready", f"round {i}"
                pub = Publisher(ctx, ping, M.UInt8MultiArray, publisher_id="init")
                size = 100_000 if i % 3 == 0 else 8
                pub.publish(M.UInt8MultiArray(data=np.full(size, i % 256, dtype=np.uint8)))
                got: list = []
                end = time.monotonic() + 10
                while not got and time.monotonic() < end:
                    if select.select([waker.fd], [], [], 0.5)[0]:
                        waker.serve(lambda got=got, sub=sub: got.extend(sub.take()), sub.has_news)
                assert _line(echo) == "done", f"round {i}: the echo never saw our ping"
                assert [(m.data.size, int(m.data[0])) for m in got] == [(size, i % 256)], f"round {i}: no reply woke us"
            finally:
                for part in (sub, pub, waker):
                    if part is not None:
                        part.close()
    finally:
        echo.stdin.close()
        try:
            echo.wait(10)
        except subprocess.TimeoutExpired:
            echo.kill()
            echo.wait()
