"""The torn-read check shared by the loan and streaming-copy tests: a writer process publishes
frames whose label carries their CRC forever; it is SIGKILLed after ``kill_after`` seconds (mid
copy with good probability), and nothing a subscriber can then see may be torn."""
from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
import zlib
from collections.abc import Callable

from emos import msgs as M
from emos.transport import ring as R
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker

FORK = mp.get_context("fork")


def check_intact(msgs) -> int:
    """Assert each ``UInt8MultiArray``'s data matches the CRC in its label; return how many."""
    for m in msgs:
        seq, crc = m.layout.dim[0].label.split(":")
        assert zlib.crc32(m.data.data) == int(crc), f"torn message {seq}"
    return len(msgs)


def sigkill_writer_and_check(ctx: RunContext, writer: Callable[..., None], size: int, kill_after: float, tracked: bool = False,
                             armed: Callable[[], bool] | None = None) -> int:
    """Run ``writer(run_dir, run_id, size, ready)`` publishing on /stream as "writer", read and
    check for ``kill_after`` s, SIGKILL it, then check everything still visible: the queue, the
    latest message and the ring's next number (not written, or complete and intact).
    ``tracked``: the subscriber has a wake-up token, so the writer sees how far it read (what
    recent-slot reuse needs, ``ring.py``); it drains its wake-ups as it reads. ``armed``: read
    until it says the writer reached the state under test (bounded only against a hang), then
    the ``kill_after`` s."""
    ready = FORK.Event()
    proc = FORK.Process(target=writer, args=(str(ctx.run_dir), ctx.run_id, size, ready))
    proc.start()
    waker = Waker(ctx) if tracked else None
    try:
        sub = Subscriber(ctx, "/stream", M.UInt8MultiArray, waker=waker, queue_size=8)
        assert ready.wait(60)
        checked = 0

        def read() -> int:
            if waker is not None:
                waker.drain()  # announcements: the writer's ring (and each one it grows to)
            return check_intact(sub.take())

        hang = time.monotonic() + 60
        while armed is not None and not armed() and time.monotonic() < hang:
            checked += read()
        end = time.monotonic() + kill_after
        while time.monotonic() < end:
            checked += read()
        assert proc.is_alive(), f"the writer died by itself (exit code {proc.exitcode})"
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        checked += check_intact(sub.take())
        latest = sub.latest()
        if latest is not None:
            check_intact([latest])
        assert sub.take() == []
        src = sub.sources.get("writer")
        if src is not None:
            status, payload, _ = src.ring.read(src.ring.head)
            assert status in (R.NOT_READY, R.LAPPED, R.OK)
            if status == R.OK:
                check_intact([M.decode(M.UInt8MultiArray, payload)])
        sub.close()
        return checked
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
        if waker is not None:
            waker.close()
