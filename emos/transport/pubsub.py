"""Publishers and subscribers over shared-memory rings.

One ring per (topic, publisher). A publisher with a stable ``publisher_id`` (a component's name)
re-opens its ring after a restart and continues the message numbering, so subscribers notice
nothing but a gap in time. Subscribers find publishers by listing the run's segments. A
subscriber with a waker rescans when a publisher announced itself (or left) through it, and at
least every ``RESCAN_EVERY_NS`` as a safety net; one without a waker rescans when ``/dev/shm``
changed (its mtime, one ``stat``).

Nothing in ``/dev/shm`` is trusted (see :mod:`emos.transport.trust`): rings are opened through
one validated path (``Ring.attach``), and a ring that is not ours, does not hold together, or
turns out damaged while being read is dropped with a rate-limited warning naming the topic and
segment; the subscriber keeps delivering from every other publisher of the topic.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from emos.errors import TransportError
from emos.msgs import codec
from emos.msgs.registry import canonical_name
from emos.transport import ring as R
from emos.transport.context import SHM_DIR, RunContext, decode_name, encode_name
from emos.transport.fence import full_fence
from emos.transport.generations import create_generation, latest_own_generation
from emos.transport.limits import check_topic_name
from emos.transport.loans import LOAN_MIN_BYTES, LOANS_PER_SUBSCRIBER, LoanBook, PublisherLoan
from emos.transport.ring import MessageTooLarge as MessageTooLarge  # re-exported; one class for the ring's and the topic's limit
from emos.transport.screen import SegmentScreen
from emos.transport.trust import UntrustedFile, rate_limited, remove_owned
from emos.transport.waker import ANNOUNCE, Waker, WakeSender

log = logging.getLogger("emos.transport")

DEFAULT_CAPACITY = 64 * 1024
MAX_MESSAGE_BYTES = 512 * 1024 * 1024
_MTIME_GRANULARITY_NS = 50_000_000  # well above any kernel's timestamp tick
# An announcement can be lost only to a FIFO full of wake-ups (a reader stopped for a long
# time); the periodic rescan bounds how late such a reader finds a new publisher.
RESCAN_EVERY_NS = 1_000_000_000
REJECT_LOG_PERIOD_S = 10.0  # a publisher of the wrong type is logged at most this often, with a count
_SCAN_ATTEMPTS = 4  # listings per rescan while rings vanish under it (each grow can do that once)
# Messages at least this big are announced before they are copied, and lingering readers are
# woken as the copy starts (waker module doc, "Long writes"); smaller copies take a few
# microseconds, less than the announcement and the early wake-up would cost.
ANNOUNCE_BYTES = 128 * 1024
# Frames up to this size are written by one C call (``_ccodec.ring_publish``: encode, claim, copy,
# commit, fence) and read by one per batch (``ring_take``, below the loan threshold): the Python
# path costs about 15 interpreter calls per message each way (docs/ipc.md, "Small messages").
# Bigger frames keep the Python path (announcement, streaming copies, loans) unchanged.
SMALL_FRAME_BYTES = 64 * 1024
_C = R.RING_C  # None: no C codec, or EMOS_CODEC=python
_ring_publish = None if _C is None else _C.ring_publish
_ring_take = None if _C is None else _C.ring_take
_ring_write = None if _C is None else _C.ring_write
_COPY_NS_PER_BYTE = 1.0  # first guess of a copy's speed (1 GB/s): measured after each long write
_ANNOUNCE_MARGIN_NS = 100_000  # slack on the deadline for preemption of the writer


class TopicTypeError(TransportError, TypeError):
    """Two ends of a topic disagree on its message type."""


def _fingerprint(cls: type) -> str:
    fingerprint: str = cls._emos_fingerprint  # type: ignore[attr-defined]  # set by @message_type
    return fingerprint


def parse_segment(ctx: RunContext, name: str) -> tuple[str, str, int] | None:
    """``(topic, publisher_id, generation)`` of one of this run's segment names."""
    if not name.startswith(ctx.shm_prefix):
        return None
    parts = name[len(ctx.shm_prefix) :].split(".")
    if len(parts) != 3 or not parts[2].startswith("g") or not parts[2][1:].isdigit():
        return None
    return decode_name(parts[0]), decode_name(parts[1]).lstrip("/"), int(parts[2][1:])


class Publisher:
    """Writes messages of one type to one topic."""

    def __init__(self, ctx: RunContext, topic: str, msg_cls: type, publisher_id: str | None = None, depth: int = 10,
                 max_bytes: int = MAX_MESSAGE_BYTES, capacity: int = DEFAULT_CAPACITY, reuse_recent: bool = False):
        """``capacity``: the slot size (bytes) of the first ring; it grows as messages need.
        ``reuse_recent``: big messages may go to the slot of the message before last when every
        reader has read it (``ring.py``, "Recent slots"): what a volatile topic wants; a
        transient-local one keeps its whole history for late joiners."""
        if not 0 < capacity <= max_bytes:
            raise ValueError(f"Publisher on {topic!r}: capacity must be 1..{max_bytes} bytes, got {capacity!r}")
        self.ctx = ctx
        self._first_capacity = int(capacity)
        self.topic = topic
        self.msg_cls = msg_cls
        self.type_name = canonical_name(msg_cls)
        self.publisher_id = publisher_id or f"pid{os.getpid()}-{id(self):x}"
        self.anonymous = publisher_id is None
        check_topic_name(topic, self.publisher_id)
        self.depth = max(int(depth), 2)
        self.max_bytes = max_bytes
        self.sender = WakeSender(ctx)
        self._waiters_version = -1
        self._ns_per_byte = _COPY_NS_PER_BYTE  # how fast our long copies run (see _announce_write)
        self._loan_open = False  # a PublisherLoan holds the next message (single writer)
        self.reuse_recent = bool(reuse_recent)
        self.ring = self._open_or_create()
        self._announce()

    # -- segment management ----------------------------------------------------------------------
    def _open_or_create(self) -> R.Ring:
        """Re-open our ring after a restart if it is intact, else start a fresh generation."""
        gen = latest_own_generation(self.ctx, self.topic, self.publisher_id)
        first = 0
        if gen is not None:
            name = self.ctx.segment_name(self.topic, self.publisher_id, gen)
            try:
                ring = R.Ring.attach(name, generation=gen)
                problem = "it was never fully initialised" if ring is None else None
            except (R.RingError, UntrustedFile) as exc:
                ring, problem = None, str(exc)
            if ring is not None:
                if ring.fingerprint != _fingerprint(self.msg_cls):
                    ring.close()
                    raise TopicTypeError(
                        f"topic {self.topic!r}: publisher {self.publisher_id!r} publishes {self.type_name}, "
                        f"but its existing ring carries {ring.type_name}"
                    )
                problem = ring.damage()
                if problem is None:
                    ring.set_writer_pid(os.getpid())
                    return ring
                first = ring.head  # the header itself passed its checks: keep numbering on
                ring.close()
            log.warning("topic %s: ring %s of publisher %s is damaged (%s); starting generation %d", self.topic, name, self.publisher_id, problem, gen + 1)
            left = remove_owned(SHM_DIR / name)
            if left is not None:
                log.warning("topic %s: cannot remove damaged ring %s: %s", self.topic, name, left)
            gen += 1
        # Subscribers (re-)register from the subscriber directory in _announce, owed from ``first``.
        ring = self._create_ring(gen or 0, self.depth, self._first_capacity, _fingerprint(self.msg_cls), self.type_name, first)
        ring.set_writer_pid(os.getpid())
        return ring

    def _create_ring(self, generation: int, depth: int, capacity: int, fingerprint: str, type_name: str, first: int) -> R.Ring:
        return create_generation(self.ctx, self.topic, self.publisher_id, generation, depth, capacity, fingerprint, type_name, first)

    def _announce(self) -> None:
        """Register every known subscriber of the topic in our ring and wake them once."""
        for entry in self.ctx.subscriber_dir(self.topic).iterdir():
            try:
                self.ring.add_waiter(int(entry.name, 16))
            except ValueError:
                continue
        self._sync_waiters()
        self._wake(ANNOUNCE)

    def _grow(self, nbytes: int) -> None:
        old = self.ring
        capacity = max(2 * old.capacity, int(nbytes * 1.25))
        # Carry the messages still held by the old ring over, under the same numbers, so a
        # subscriber that finds only the new generation (or follows late) loses nothing.
        start = max(old.first, old.head - old.slot_count)
        carried: list[tuple[bytearray, int]] = []
        for n in range(start, old.head):
            try:
                status, read, stamp = old.read(n)
            except R.RingCorrupt:  # scribbled on while we ran: carry an empty message in its place
                status, read, stamp = R.CORRUPT, None, 0
            if status == R.LAPPED:
                # Overwritten by a recent-slot write (every reader had read it): carry only what
                # follows, so no reader is handed a hole; the numbering stays dense.
                carried.clear()
                start = n + 1
                continue
            carried.append((read if status == R.OK and read is not None else bytearray(), stamp))
        new = self._create_ring(old.generation + 1, old.slot_count, capacity, old.fingerprint, old.type_name, start)
        new.add_untracked(old.untracked)  # readers we cannot track follow us here (_Source.switch_to)
        for payload, stamp in carried:
            m, buf = new.begin(len(payload))
            buf[:] = payload
            buf.release()
            new.commit(m, len(payload), stamp)
        new.set_writer_pid(os.getpid())
        for token, mark in old.waiter_marks().items():
            new.add_waiter(token, mark=max(mark, start))
        old.set_moved_to(new.generation)
        self.ring = new
        old.unlink()
        old.close()
        # Announce the move: a subscriber that had not found the old generation yet may have
        # missed both names, since a directory listing that runs while one name is created and
        # another removed may return neither; the announcement makes it list again, now that
        # nothing of ours changes. (Without it such a subscriber waited for a wake-up that
        # never came: the ping-pong bench's start-up hang at sizes that grow the ring.)
        self._announce()
        log.info("topic %s: ring of %s grew to %d B slots for a %d B message", self.topic, self.publisher_id, new.capacity, nbytes)

    # -- publishing ------------------------------------------------------------------------------
    def loan(self, msg_cls: type, shape: tuple[int, ...], dtype: Any = np.uint8, field: str = "data", **fields: Any) -> PublisherLoan:
        """A message whose ``field`` array (``shape``, ``dtype``) is a writable view of the next
        ring slot, published when the ``with`` block ends (abandoned if it raises)::

            with pub.loan(Image, shape=(480, 640, 3), encoding="rgb8") as msg:
                camera.read_into(msg.to_numpy())

        Other fields may be passed here or set inside the block; the message and its arrays
        are valid only inside it. See :class:`emos.transport.loans.PublisherLoan`."""
        if self._loan_open:
            raise RuntimeError(f"topic {self.topic!r}: a loan of publisher {self.publisher_id!r} is still open (one at a time)")
        return PublisherLoan(self, msg_cls, shape, dtype, field, fields)

    def _begin_loan(self, nbytes: int) -> R.Ring:
        """Our ring, grown to hold ``nbytes`` if needed, held for a loan until ``_end_loan``."""
        if self._loan_open:
            raise RuntimeError(f"topic {self.topic!r}: a loan of publisher {self.publisher_id!r} is still open (one at a time)")
        if nbytes > self.ring.capacity:
            if nbytes > self.max_bytes:
                raise MessageTooLarge(f"topic {self.topic!r}: a loaned {self.type_name} of {nbytes} B exceeds the limit of {self.max_bytes} B")
            self._grow(nbytes)
        self._loan_open = True
        return self.ring

    def _end_loan(self) -> None:
        self._loan_open = False

    def publish(self, msg: Any) -> int:
        """Write ``msg``; returns its message number on this publisher's ring."""
        if self._loan_open:
            raise RuntimeError(f"topic {self.topic!r}: publish while a loan of publisher {self.publisher_id!r} is open (finish the loan first)")
        if not isinstance(msg, self.msg_cls):
            raise TopicTypeError(f"topic {self.topic!r} carries {self.type_name}, got {type(msg).__name__}")
        stamp = time.time_ns()
        if _ring_publish is not None:
            ring = self.ring
            got = _ring_publish(msg, ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, stamp, SMALL_FRAME_BYTES)
            if type(got) is int:  # written and committed, fence included: wake who parked
                if ring.q[R._WAITERS_VER] != self._waiters_version:
                    self._sync_waiters()
                if self.sender.fds:
                    for token in self.sender.wake(fenced=True):
                        self._drop_waiter(token)
                return got
            # Not written (the ring untouched): big, a ring to grow, a slot only the Python path
            # takes (a loan pins it), or a message the C encoder leaves to the Python codec.
            enc = got if got is not NotImplemented else codec.encode_python(msg)
        else:
            enc = codec.encode(msg)
        nbytes = enc.nbytes
        if nbytes > self.ring.capacity:
            if nbytes > self.max_bytes:
                raise MessageTooLarge(f"topic {self.topic!r}: a {self.type_name} of {nbytes} B exceeds the limit of {self.max_bytes} B")
            self._grow(nbytes)
        ring = self.ring
        started = self._announce_write(ring, nbytes) if nbytes >= ANNOUNCE_BYTES else 0  # (no call for small ones)
        if _ring_write is not None:
            # Claim, copy (streaming past codec.STREAM_MIN_BYTES), commit and fence in one C call;
            # None: the ring untouched, for the Python path below (a slot to search for, say).
            n = _ring_write(enc, ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity, stamp,
                            R.RECENT_MIN_BYTES if self.reuse_recent else 0, codec.STREAM_MIN_BYTES)
            if n is not None:
                self._committed(nbytes, started)
                return int(n)
        n, buf = ring.begin(nbytes, self.reuse_recent)
        try:
            # Arrays past codec.STREAM_MIN_BYTES go in with streaming stores: where the slots
            # a topic cycles through outgrow the last-level cache (docs/ipc.md).
            enc.write_into(buf, stream=True)
        except BaseException:
            ring.abandon()
            raise
        finally:
            buf.release()
        self._finish(ring, n, nbytes, stamp, started)
        return n

    def _announce_write(self, ring: R.Ring, nbytes: int) -> int:
        """For a long copy about to start: announce when it should end and wake the lingering
        readers now (waker module doc, "Long writes"); returns its start time (0: not announced)."""
        if nbytes < ANNOUNCE_BYTES:
            return 0
        now = time.monotonic_ns()
        ring.announce(now + int(2 * nbytes * self._ns_per_byte) + _ANNOUNCE_MARGIN_NS)
        if self.sender.fds:
            self.sender.wake_early()
        return now

    def _finish(self, ring: R.Ring, n: int, nbytes: int, stamp: int, started: int) -> None:
        """Commit message ``n`` and wake the readers that are not spinning."""
        ring.commit(n, nbytes, stamp)
        # Our head store before we read the waiter table: a subscriber registers (stores), then
        # reads head; with a fence on both sides one of us sees the other, so a subscriber that
        # registered just now either reads this message or is woken for it (Dekker again).
        full_fence()
        self._committed(nbytes, started)

    def _committed(self, nbytes: int, started: int) -> None:
        """After a commit and its full fence: learn the copy's speed, wake who is not spinning."""
        if started:
            took = time.monotonic_ns() - started
            self._ns_per_byte = 0.75 * self._ns_per_byte + 0.25 * took / nbytes
        ring = self.ring
        if ring.q[R._WAITERS_VER] != self._waiters_version:
            self._sync_waiters()
        if self.sender.fds:
            dead = self.sender.wake(fenced=True)
            for token in dead:
                self._drop_waiter(token)

    def _sync_waiters(self) -> None:
        version, tokens = self.ring.waiters()
        self._waiters_version = version
        for token in self.sender.sync(tokens):
            self._drop_waiter(token)

    def _wake(self, what: bytes) -> None:
        for token in self.sender.wake(what):
            self._drop_waiter(token)

    def _drop_waiter(self, token: int) -> None:
        self.ring.remove_waiter(token)
        try:
            (self.ctx.subscriber_dir(self.topic) / f"{token:016x}").unlink()
        except FileNotFoundError:
            pass

    @property
    def segment(self) -> str:
        return self.ring.name

    def close(self) -> None:
        """Stop publishing. Anonymous publishers remove their ring; named ones keep it for a restart."""
        if self.ring is not None:
            if self.anonymous:
                self.ring.unlink()
                self._wake(ANNOUNCE)  # subscribers let go of the ring
            self.ring.close()
            self.ring = None  # type: ignore[assignment]
        self.sender.close()


class _Source:
    """One publisher's ring as seen by one subscriber."""

    __slots__ = ("ring", "cursor", "publisher_id", "base", "loans", "track")

    def __init__(self, ring: R.Ring, cursor: int, publisher_id: str, base: str, loans: int, token: int | None):
        self.ring = ring
        self.cursor = cursor
        self.publisher_id = publisher_id
        self.base = base
        self.loans = LoanBook(ring, loans) if loans > 0 else None
        self.track = _NOT_COUNTED
        self._track(token)

    def _track(self, token: int | None, counted: bool = False) -> None:
        """Tell the writer how far we read (``ring.py``, "Recent slots"): through the cursor word
        of our wake-up ``token`` in the ring if it is registered there, else by being counted as
        a reader it cannot track (which keeps its whole history for us). ``counted``: the ring
        already counts us (a grown ring carries its predecessor's count over)."""
        at = self.ring.cursor_index(token) if token is not None else None
        if at is None:
            if not counted:
                self.ring.add_untracked(1)
            self.track = _UNTRACKED
        else:
            if counted:
                self.ring.add_untracked(-1)
            self.track = at
            self.report()

    def report(self) -> None:
        """Store our cursor in the ring's cursor word (cheap: one store; for the hot path)."""
        if self.track >= 0:
            self.ring.q[self.track] = self.cursor

    def switch_to(self, ring: R.Ring, base: str, loans: int, token: int | None) -> None:
        """Follow the publisher to the next generation of its ring."""
        counted = self.track == _UNTRACKED  # the publisher carried the count over when it grew
        self.close()
        self.ring, self.base = ring, base
        self.loans = LoanBook(ring, loans) if loans > 0 else None
        self._track(token, counted)

    def read(self, n: int) -> tuple[int, np.ndarray | memoryview | None, int]:
        """Message ``n``: a loaned view when it is big and an entry is free, else a copy.

        Either way the bytes are read-only, so code that works on small (copied) messages
        behaves the same on big (loaned) ones.
        """
        ring, book = self.ring, self.loans
        if book is not None and book.free and ring.length_of(n) >= LOAN_MIN_BYTES:
            got = book.loan(n)
            if got is not None:
                return got
        status, buf, stamp = ring.read(n)
        return status, (None if buf is None else memoryview(buf).toreadonly()), stamp

    def close(self) -> None:
        if self.loans is not None:
            self.loans.close()
            self.loans = None
        if self.track == _UNTRACKED and self.ring.mm is not None:
            self.ring.add_untracked(-1)
        self.track = _NOT_COUNTED
        self.ring.close()


# _Source.track when the source has no cursor word: counted in the ring's untracked readers, or not.
_UNTRACKED, _NOT_COUNTED = -1, -2


class Subscriber:
    """Reads one topic from every publisher on it.

    ``transient_local`` delivers up to ``queue_size`` messages published before it joined
    (ROS's TRANSIENT_LOCAL durability); otherwise only later ones.

    Payloads of ``LOAN_MIN_BYTES`` or more arrive zero-copy: read-only views into the
    publisher's ring, each pinning its slot until the last array viewing it is garbage
    collected. ``loans`` (per publisher) bounds how many such messages this subscriber holds at
    once; beyond that, and with ``loans=0``, messages are copied.
    """

    def __init__(self, ctx: RunContext, topic: str, msg_cls: type, waker: Waker | None = None, queue_size: int = 10, transient_local: bool = False, loans: int = LOANS_PER_SUBSCRIBER):
        self.ctx = ctx
        self.loans = max(int(loans), 0)
        self.topic = topic
        self.msg_cls = msg_cls
        self.queue_size = max(int(queue_size), 1)
        self.transient_local = transient_local
        self.waker = waker
        self.sources: dict[str, _Source] = {}
        self.dropped = 0
        self.undecodable = 0  # messages that arrived but did not decode as ``msg_cls``
        self._created_ns = time.monotonic_ns()
        self._shm_mtime = -1
        self._scanned_at_ns = 0
        self._announcements = -1
        self._scanned_once = False
        self._rejected: dict[str, tuple[int, float, str]] = {}  # segment -> (times seen, last logged, type)
        self._prefix = f"{ctx.shm_prefix}{encode_name(topic)}."
        self._screen = SegmentScreen(topic, self._prefix, lambda name: parse_segment(ctx, name))
        self._interest: Path | None = None
        if waker is not None:
            self._interest = self.ctx.subscriber_dir(topic) / f"{waker.token:016x}"
            self._interest.touch(mode=0o600)
            waker.watch(self)
        self.rescan(force=True)

    # -- discovery --------------------------------------------------------------------------------
    def rescan(self, force: bool = False) -> None:
        if not force and self.waker is not None:
            # Hot path, every read: publishers announce themselves through our waker, which
            # saves the stat below (a few microseconds per message).
            if self.waker.announcements == self._announcements and time.time_ns() - self._scanned_at_ns < RESCAN_EVERY_NS:
                return
            force = True
        mtime = os.stat(SHM_DIR).st_mtime_ns
        # An unchanged directory mtime proves nothing new appeared only if our last scan came
        # clearly after that mtime: tmpfs timestamps are coarse (a jiffy), so a segment created
        # in the same tick as our scan leaves the mtime unchanged.
        if not force and mtime == self._shm_mtime and self._scanned_at_ns - mtime > _MTIME_GRANULARITY_NS:
            return
        if self.waker is not None:
            self._announcements = self.waker.announcements
        self._shm_mtime = mtime
        self._scanned_at_ns = time.time_ns()
        # A publisher's ring may vanish between our listing and our open (it grew: the next
        # generation exists before the old one is unlinked), or be listed before it is
        # initialised: fall back to an older generation, and list again if that vanished too.
        # Skipping it would lose the wake-up that brought us here (the start-up hang of the
        # ping-pong bench: the first message went to a generation nobody had found).
        initial = not self._scanned_once
        self._scanned_once = True
        listed: set[str] = set()
        for _ in range(_SCAN_ATTEMPTS):
            found = self._screen.candidates({pub: src.ring.name for pub, src in self.sources.items()})
            incomplete = False
            for pub, gens in found.items():
                listed.update(name for _, name in gens)
                src = self.sources.get(pub)
                if src is not None and (src.ring.name == gens[0][1] or src.ring.moved_to or not src.ring.unlinked):
                    # Up to date, or moved or moving to a bigger ring: ``_follow`` handles that
                    # on the next read, keeping the cursor (numbers carry over). (Whether our
                    # ring still exists is asked of its descriptor: a listing can miss it.)
                    continue
                if gens[0][1] in self._rejected:
                    self._reject(gens[0][1], pub, None)
                    continue
                ring = None
                for gen, name in gens:
                    ring = self._screen.attach(name, gen)
                    if ring is not None:
                        break
                    incomplete = True
                if ring is None:
                    continue
                if not initial and ring.fingerprint != _fingerprint(self.msg_cls):
                    # A publisher that appeared later with the wrong type: that one peer is refused
                    # (logged, rate-limited) and the topic goes on with the others.
                    self._reject(ring.name, pub, ring.type_name)
                    ring.close()
                    continue
                self._check_type(ring, pub)
                mark = self._register(ring)
                if src is not None:
                    # Our ring is gone without moving: the publisher restarted on a fresh
                    # generation (its old ring was damaged). Numbering may start over.
                    src.close()
                self.sources[pub] = _Source(ring, self._start_cursor(ring, mark), pub, ring.name, self.loans, self._token(mark))
            if not incomplete:
                break
        for gone in [n for n in self._rejected if n not in listed]:
            del self._rejected[gone]
        # Forget publishers whose ring disappeared (removed at the end of a run).
        for pub in [p for p in self.sources if p not in found]:
            src = self.sources[pub]
            if src.ring.moved_to or not src.ring.unlinked:
                continue
            src.close()
            del self.sources[pub]

    def _reject(self, segment: str, pub: str, type_name: str | None) -> None:
        count, logged_at, type_name = self._rejected.get(segment, (0, float("-inf"), type_name or "?"))
        count += 1
        now = time.monotonic()
        if now - logged_at >= REJECT_LOG_PERIOD_S:
            log.error(
                "topic %s: ignoring publisher %r, which sends %s where this subscriber expects %s (seen %d time(s))",
                self.topic, pub, type_name, canonical_name(self.msg_cls), count,
            )
            logged_at = now
        self._rejected[segment] = (count, logged_at, type_name)
    def _drop(self, src: _Source, exc: BaseException) -> None:
        """Stop reading a ring that failed (damaged or forged); other publishers carry on."""
        if self.sources.get(src.publisher_id) is src:
            del self.sources[src.publisher_id]
        name = src.ring.name
        try:
            src.close()
        except Exception as close_exc:  # a ring we give up on must not take the subscriber with it
            log.debug("topic %s: closing dropped ring %s: %s", self.topic, name, close_exc)
        self._screen.reject(name, f"dropped while reading: {type(exc).__name__}: {exc}")

    def _check_type(self, ring: R.Ring, pub: str) -> None:
        if ring.fingerprint != _fingerprint(self.msg_cls):
            ring.close()
            raise TopicTypeError(
                f"topic {self.topic!r}: subscriber expects {canonical_name(self.msg_cls)}, "
                f"publisher {pub!r} sends {ring.type_name}"
            )

    def _register(self, ring: R.Ring) -> int | None:
        """Register our wake-up in ``ring``; returns the first message number owed to us."""
        if self.waker is None:
            return None
        if not ring.add_waiter(self.waker.token):
            log.warning("topic %s: ring %s has no free wake-up slot; this subscriber will poll", self.topic, ring.name)
            return None
        return ring.mark_of(self.waker.token)

    def _token(self, mark: int | None) -> int | None:
        """Our wake-up token if ``_register`` just registered it in a ring (it gave a mark)."""
        return None if mark is None or self.waker is None else self.waker.token

    def _start_cursor(self, ring: R.Ring, mark: int | None) -> int:
        """Where reading a newly found ring starts.

        With a waker, at the mark the ring holds for our token: the publisher registered us
        when it appeared (so everything it wrote is ours), or we registered ourselves just now
        (so the next message is). Registration and publishing are ordered by fences on both
        sides, so no message falls between the mark and the wake-ups. Without a waker, by
        creation time (a monotonic clock, shared by every process of the machine).
        """
        head, first = ring.head, ring.first
        if self.transient_local:
            return max(first, head - min(self.queue_size, ring.slot_count))
        if mark is not None:
            return min(max(mark, first), head)
        if int(ring.u64[R._CREATED]) >= self._created_ns:
            return first  # a publisher that appeared after us: everything it wrote is new
        return head

    def _follow(self, src: _Source) -> bool:
        """Switch to the next generation of a ring that grew; ``False`` if the source was dropped."""
        while src.ring.moved_to:
            gen = src.ring.moved_to
            if gen <= src.ring.generation:
                raise R.RingCorrupt(f"ring {src.ring.name}: says it moved back to generation {gen}")
            name = self.ctx.segment_name(self.topic, src.publisher_id, gen)
            new = self._screen.attach(name, gen) or self._newest_after(src)
            if new is None:
                self._drop_quietly(src)
                return False
            name = new.name
            mark = self._register(new)
            src.switch_to(new, name, self.loans, self._token(mark))
            if src.cursor < new.first:
                self.dropped += new.first - src.cursor
                src.cursor = new.first
            elif src.cursor > new.head:
                raise R.RingCorrupt(f"ring {name}: head {new.head} is behind our cursor {src.cursor}")
        return True

    def _newest_after(self, src: _Source) -> R.Ring | None:
        """The publisher's newest generation past ``src``'s: the ring grew again (and the
        generation it first moved to is gone) before we followed."""
        found = self._screen.candidates({})
        for gen, name in found.get(src.publisher_id, []):
            if gen <= src.ring.generation:
                break
            ring = self._screen.attach(name, gen)
            if ring is not None:
                return ring
        return None

    def _drop_quietly(self, src: _Source) -> None:
        if self.sources.get(src.publisher_id) is src:
            del self.sources[src.publisher_id]
        src.close()
        self._scanned_at_ns = 0  # rescan on the next read

    # -- reading -----------------------------------------------------------------------------------
    def take_raw(self) -> list[tuple[int, Any, str]]:
        """Every new message as ``(stamp_ns, payload, publisher_id)``, oldest first.

        ``payload`` is a read-only buffer (a loaned ndarray or a memoryview of a copy) for
        :func:`emos.msgs.codec.decode`.
        """
        self.rescan()
        out: list[tuple[int, Any, str]] = []
        for src in list(self.sources.values()):
            try:
                self._drain(src, out)
            except Exception as exc:  # noqa: BLE001 - one bad ring must not stop the topic
                self._drop(src, exc)
        if len(self.sources) > 1:
            out.sort(key=lambda item: item[0])
        if len(out) > self.queue_size:
            self.dropped += len(out) - self.queue_size
            out = out[-self.queue_size :]
        return out

    def take_raw_from(self, publisher_id: str) -> tuple[list[tuple[int, Any, str]], int]:
        """New messages of one publisher only, and its ring's writer pid (0 if it has no ring).

        Messages of the other publishers are skipped unread; for readers that trust one writer
        (the supervisor reads a component's heartbeat only from the component itself).
        """
        self.rescan()
        out: list[tuple[int, Any, str]] = []
        for pub, src in list(self.sources.items()):
            try:
                if pub == publisher_id:
                    self._drain(src, out)
                else:
                    src.cursor = max(src.cursor, src.ring.head)
                    src.report()
            except Exception as exc:  # noqa: BLE001 - one bad ring must not stop the reader
                self._drop(src, exc)
        current = self.sources.get(publisher_id)
        return out[-self.queue_size :], (current.ring.writer_pid if current is not None else 0)

    def _drain(self, src: _Source, out: list[tuple[int, Any, str]]) -> None:
        # Drain the current generation before following a move, so nothing written there is lost.
        for _ in range(2):
            ring = src.ring
            head = ring.head
            if head - src.cursor > ring.slot_count:
                self.dropped += head - ring.slot_count - src.cursor
                src.cursor = head - ring.slot_count
            while src.cursor < head:
                if _ring_take is not None:
                    # Small messages in one C call; it stops at anything else (a big message
                    # to loan, one not written yet, a slot that does not hold together), which
                    # the Python path below reads as before.
                    src.cursor, lapped = _ring_take(ring.mm, ring.depth, ring.physical_slots, ring.data_offset, ring.stride, ring.capacity,
                                                    src.cursor, head, LOAN_MIN_BYTES, out, src.publisher_id)
                    if lapped:
                        self.dropped += lapped
                    if src.cursor >= head:
                        break
                    # It stopped at a big message (or one not written yet, or damaged): loan it
                    # at once (one C call, ring_loan); a loan book with no free entry copies it.
                    book = src.loans
                    got = book.loan(src.cursor) if book is not None and book.free else None
                    status, buf, stamp = got if got is not None else src.read(src.cursor)
                else:
                    status, buf, stamp = src.read(src.cursor)
                if status == R.OK and buf is not None:
                    out.append((stamp, buf, src.publisher_id))
                    src.cursor += 1
                elif status == R.LAPPED:
                    self.dropped += 1
                    src.cursor += 1
                else:
                    break  # a writer died mid-message: nothing after it exists yet
            if src.track >= 0:  # src.report(), inlined: every take of every topic passes here
                ring.q[src.track] = src.cursor
            if not ring.moved_to or not self._follow(src):
                return

    def has_news(self) -> bool:
        """Whether a publisher we know has written past our cursor (cheap: for spin loops)."""
        for src in self.sources.values():
            q = src.ring.q
            if q[R._HEAD] > src.cursor or q[R._MOVED_PID] & 0xFFFFFFFF:
                return True
        return False

    def busy_until(self) -> int:
        """The latest deadline a publisher we read announced for a long write in progress
        (``time.monotonic_ns``), or 0: the waker spins until then (waker module doc)."""
        best = 0
        for src in self.sources.values():
            until = src.ring.q[R._BUSY]
            if until > best:
                best = until
        return best

    def take(self) -> list[Any]:
        """Every new message, decoded, oldest first (at most ``queue_size``)."""
        return [msg for msg, _, _ in self.take_with_info()]

    def take_with_info(self) -> list[tuple[Any, int, str]]:
        out = []
        for stamp, buf, pub in self.take_raw():
            msg = self._decode(buf, pub)
            if msg is not None:
                out.append((msg, stamp, pub))
        return out

    def _decode(self, buf: Any, pub: str) -> Any | None:
        """``buf`` decoded, or ``None`` (counted and logged) if it is not a ``msg_cls``."""
        try:
            return codec.decode(self.msg_cls, buf)
        except codec.DecodeError as exc:
            self.undecodable += 1
            self._screen.warn.warning(f"decode:{pub}", "topic %s: skipping a message from %s that does not decode (%d so far): %s", self.topic, pub, self.undecodable, exc)
            return None

    def latest_raw(self) -> tuple[int, Any, str] | None:
        """The newest message across publishers, skipping any backlog."""
        self.rescan()
        best: tuple[int, Any, str] | None = None
        for src in list(self.sources.values()):
            try:
                got = self._latest_of(src)
            except Exception as exc:  # noqa: BLE001 - one bad ring must not stop the topic
                self._drop(src, exc)
                continue
            if got is not None and (best is None or got[0] > best[0]):
                best = got
        return best

    def _latest_of(self, src: _Source) -> tuple[int, Any, str] | None:
        if not self._follow(src):
            return None
        ring = src.ring
        # The newest slot may belong to a writer that died mid-copy; the one before it is then
        # the newest complete message.
        for n in (ring.head - 1, ring.head - 2):
            if n < max(src.cursor, ring.first):
                break
            status, buf, stamp = src.read(n)
            if status == R.OK and buf is not None:
                src.cursor = n + 1
                src.report()
                return (stamp, buf, src.publisher_id)
            if status == R.LAPPED:
                break
        return None

    def latest(self) -> Any | None:
        item = self.latest_raw()
        return None if item is None else self._decode(item[1], item[2])

    def publishers(self) -> list[str]:
        self.rescan()
        return sorted(self.sources)

    def writer_pids(self) -> list[int]:
        """Process ids of the publishers found (0 where a ring records none)."""
        return [src.ring.writer_pid for src in list(self.sources.values())]

    def close(self) -> None:
        for src in self.sources.values():
            if self.waker is not None:
                try:
                    src.ring.remove_waiter(self.waker.token)
                except (OSError, ValueError, TypeError):
                    pass
            src.close()
        self.sources.clear()
        if self.waker is not None:
            self.waker.unwatch(self)
        if self._interest is not None:
            try:
                self._interest.unlink()
            except FileNotFoundError:
                pass


def list_topics(ctx: RunContext) -> dict[str, dict[str, Any]]:
    """Topics of a run: ``{topic: {"type": name, "publishers": [...]}}``."""
    topics: dict[str, dict[str, Any]] = {}
    for name in sorted(os.listdir(SHM_DIR)):
        parsed = parse_segment(ctx, name)
        if parsed is None:
            continue
        topic, pub, gen = parsed
        try:
            ring = R.Ring.attach(name, generation=gen)
        except (R.RingError, UntrustedFile) as exc:
            rate_limited.warning(f"distrust:{name}", "topic %s: ignoring segment %s: %s", topic, name, exc)
            continue
        if ring is None:
            continue
        entry = topics.setdefault(topic, {"type": ring.type_name, "publishers": []})
        if pub not in entry["publishers"]:
            entry["publishers"].append(pub)
        ring.close()
    # A stopping system removes its run directory while we read it, and any process of the run's
    # user may leave something else than a folder here: neither may fail the listing.
    try:
        folders = list((ctx.run_dir / "subs").iterdir())
    except OSError:
        folders = []
    for folder in folders:
        try:
            subscribers = len(list(folder.iterdir()))
        except OSError:
            continue
        info = topics.setdefault(decode_name(folder.name), {"type": "?", "publishers": []})
        info["subscribers"] = subscribers
    return topics


def iter_segments(ctx: RunContext) -> Iterator[Path]:
    for name in ctx.all_segments():
        yield SHM_DIR / name
