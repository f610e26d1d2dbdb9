"""Publishers and subscribers over shared-memory rings.

One ring per (topic, publisher). A publisher with a stable ``publisher_id`` (a component's name)
re-opens its ring after a restart and continues the message numbering, so subscribers notice
nothing but a gap in time. Subscribers find publishers by listing the run's segments. A
subscriber with a waker rescans when a publisher announced itself (or left) through it, and at
least every ``RESCAN_EVERY_NS`` as a safety net; one without a waker rescans when ``/dev/shm``
changed (its mtime, one ``stat``).
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from emos.msgs import codec
from emos.msgs.registry import canonical_name
from emos.transport import ring as R
from emos.transport.context import SHM_DIR, RunContext, decode_name, encode_name
from emos.transport.limits import check_topic_name
from emos.transport.loans import LOAN_MIN_BYTES, LOANS_PER_SUBSCRIBER, LoanBook
from emos.transport.waker import ANNOUNCE, WakeSender, Waker

log = logging.getLogger("emos.transport")

DEFAULT_CAPACITY = 64 * 1024
MAX_MESSAGE_BYTES = 512 * 1024 * 1024
_MTIME_GRANULARITY_NS = 50_000_000  # well above any kernel's timestamp tick
# An announcement can be lost only to a FIFO full of wake-ups (a reader stopped for a long
# time); the periodic rescan bounds how late such a reader finds a new publisher.
RESCAN_EVERY_NS = 1_000_000_000
REJECT_LOG_PERIOD_S = 10.0  # a publisher of the wrong type is logged at most this often, with a count


class TopicTypeError(TypeError):
    """Two ends of a topic disagree on its message type."""


class MessageTooLarge(ValueError):
    """A message exceeds the largest size a topic accepts."""


def _fingerprint(cls: type) -> str:
    return cls._emos_fingerprint  # type: ignore[attr-defined]


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

    def __init__(self, ctx: RunContext, topic: str, msg_cls: type, publisher_id: str | None = None, depth: int = 10, max_bytes: int = MAX_MESSAGE_BYTES):
        self.ctx = ctx
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
        self.ring = self._open_or_create()
        self._announce()

    # -- segment management ----------------------------------------------------------------------
    def _latest_generation(self) -> int | None:
        prefix = f"{self.ctx.shm_prefix}{encode_name(self.topic)}.{encode_name(self.publisher_id)}.g"
        gens = [int(n[len(prefix) :]) for n in os.listdir(SHM_DIR) if n.startswith(prefix) and n[len(prefix) :].isdigit()]
        return max(gens) if gens else None

    def _open_or_create(self) -> R.Ring:
        gen = self._latest_generation()
        if gen is not None:
            ring = R.Ring.attach(self.ctx.segment_name(self.topic, self.publisher_id, gen))
            if ring is not None:
                if ring.fingerprint != _fingerprint(self.msg_cls):
                    ring.close()
                    raise TopicTypeError(
                        f"topic {self.topic!r}: publisher {self.publisher_id!r} publishes {self.type_name}, "
                        f"but its existing ring carries {ring.type_name}"
                    )
                ring.set_writer_pid(os.getpid())
                return ring
        ring = R.Ring.create(
            self.ctx.segment_name(self.topic, self.publisher_id, 0), self.depth, DEFAULT_CAPACITY,
            _fingerprint(self.msg_cls), self.type_name,
        )
        ring.set_writer_pid(os.getpid())
        return ring

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
        new = R.Ring.create(
            self.ctx.segment_name(self.topic, self.publisher_id, old.generation + 1), old.slot_count, capacity,
            old.fingerprint, old.type_name, generation=old.generation + 1, first=start,
        )
        for n in range(start, old.head):
            status, read, stamp = old.read(n)
            # Not OK cannot happen for our own completed messages; keep the numbering dense anyway.
            payload = read if status == R.OK and read is not None else bytearray()
            m, buf = new.begin(len(payload))
            buf[:] = payload
            buf.release()
            new.commit(m, len(payload), stamp)
        new.set_writer_pid(os.getpid())
        for token in old.waiters()[1]:
            new.add_waiter(token)
        old.set_moved_to(new.generation)
        self.ring = new
        old.unlink()
        old.close()
        log.info("topic %s: ring of %s grew to %d B slots for a %d B message", self.topic, self.publisher_id, new.capacity, nbytes)

    # -- publishing ------------------------------------------------------------------------------
    def publish(self, msg: Any) -> int:
        """Write ``msg``; returns its message number on this publisher's ring."""
        if not isinstance(msg, self.msg_cls):
            raise TopicTypeError(f"topic {self.topic!r} carries {self.type_name}, got {type(msg).__name__}")
        stamp = time.time_ns()
        enc = codec.encode(msg)
        nbytes = enc.nbytes
        if nbytes > self.ring.capacity:
            if nbytes > self.max_bytes:
                raise MessageTooLarge(f"topic {self.topic!r}: a {self.type_name} of {nbytes} B exceeds the limit of {self.max_bytes} B")
            self._grow(nbytes)
        ring = self.ring
        n, buf = ring.begin(nbytes)
        try:
            enc.write_into(buf)
        finally:
            buf.release()
        ring.commit(n, nbytes, stamp)
        if ring.q[R._WAITERS_VER] != self._waiters_version:
            self._sync_waiters()
        if self.sender.fds:
            dead = self.sender.wake()
            for token in dead:
                self._drop_waiter(token)
        return n

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

    __slots__ = ("ring", "cursor", "publisher_id", "base", "loans")

    def __init__(self, ring: R.Ring, cursor: int, publisher_id: str, base: str, loans: int):
        self.ring = ring
        self.cursor = cursor
        self.publisher_id = publisher_id
        self.base = base
        self.loans = LoanBook(ring, loans) if loans > 0 else None

    def switch_to(self, ring: R.Ring, base: str, loans: int) -> None:
        """Follow the publisher to the next generation of its ring."""
        self.close()
        self.ring, self.base = ring, base
        self.loans = LoanBook(ring, loans) if loans > 0 else None

    def read(self, n: int) -> tuple[int, "np.ndarray | memoryview | None", int]:
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
        self.ring.close()


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
        self._created_ns = time.time_ns()
        self._shm_mtime = -1
        self._scanned_at_ns = 0
        self._announcements = -1
        self._scanned_once = False
        self._rejected: dict[str, tuple[int, float, str]] = {}  # segment -> (times seen, last logged, type)
        self._prefix = f"{ctx.shm_prefix}{encode_name(topic)}."
        self._interest: Path | None = None
        if waker is not None:
            self._interest = self.ctx.subscriber_dir(topic) / f"{waker.token:016x}"
            self._interest.touch(mode=0o600)
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
        initial = not self._scanned_once
        self._scanned_once = True
        latest: dict[str, tuple[int, str]] = {}
        for name in os.listdir(SHM_DIR):
            if not name.startswith(self._prefix):
                continue
            parsed = parse_segment(self.ctx, name)
            if parsed is None:
                continue
            _, pub, gen = parsed
            if pub not in latest or gen > latest[pub][0]:
                latest[pub] = (gen, name)
        for pub, (gen, name) in latest.items():
            src = self.sources.get(pub)
            if src is not None and src.ring.name == name:
                continue
            if src is not None:
                # The publisher moved to a bigger ring; ``_follow`` handles it on the next read.
                continue
            if name in self._rejected:
                self._reject(name, pub, None)
                continue
            ring = R.Ring.attach(name)
            if ring is None:
                continue
            if not initial and ring.fingerprint != _fingerprint(self.msg_cls):
                # A publisher that appeared later with the wrong type: that one peer is refused
                # (logged, rate-limited) and the topic goes on with the others.
                self._reject(name, pub, ring.type_name)
                ring.close()
                continue
            self._check_type(ring, pub)
            self._register(ring)
            self.sources[pub] = _Source(ring, self._start_cursor(ring), pub, name, self.loans)
        for gone in [n for n in self._rejected if n not in {v[1] for v in latest.values()}]:
            del self._rejected[gone]
        # Forget publishers whose ring disappeared (removed at the end of a run).
        for pub in [p for p in self.sources if p not in latest]:
            src = self.sources[pub]
            if src.ring.moved_to:
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

    def _check_type(self, ring: R.Ring, pub: str) -> None:
        if ring.fingerprint != _fingerprint(self.msg_cls):
            ring.close()
            raise TopicTypeError(
                f"topic {self.topic!r}: subscriber expects {canonical_name(self.msg_cls)}, "
                f"publisher {pub!r} sends {ring.type_name}"
            )

    def _register(self, ring: R.Ring) -> None:
        if self.waker is not None and not ring.add_waiter(self.waker.token):
            log.warning("topic %s: ring %s has no free wake-up slot; this subscriber will poll", self.topic, ring.name)

    def _start_cursor(self, ring: R.Ring) -> int:
        head = ring.head
        created = int(ring.u64[R._CREATED])
        if created >= self._created_ns:
            return ring.first  # a publisher that appeared after us: everything it wrote is new
        if self.transient_local:
            return max(ring.first, head - min(self.queue_size, ring.slot_count))
        return head

    def _follow(self, src: _Source) -> None:
        """Switch to the next generation of a ring that grew."""
        while src.ring.moved_to:
            name = self.ctx.segment_name(self.topic, src.publisher_id, src.ring.moved_to)
            new = R.Ring.attach(name)
            if new is None:
                return
            src.switch_to(new, name, self.loans)
            self._register(new)
            if src.cursor < new.first:
                self.dropped += new.first - src.cursor
                src.cursor = new.first

    # -- reading -----------------------------------------------------------------------------------
    def take_raw(self) -> list[tuple[int, Any, str]]:
        """Every new message as ``(stamp_ns, payload, publisher_id)``, oldest first.

        ``payload`` is a read-only buffer (a loaned ndarray or a memoryview of a copy) for
        :func:`emos.msgs.codec.decode`.
        """
        self.rescan()
        out: list[tuple[int, Any, str]] = []
        for src in self.sources.values():
            self._drain(src, out)
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
        for pub, src in self.sources.items():
            if pub == publisher_id:
                self._drain(src, out)
            else:
                src.cursor = max(src.cursor, src.ring.head)
        src = self.sources.get(publisher_id)
        return out[-self.queue_size :], (src.ring.writer_pid if src is not None else 0)

    def _drain(self, src: _Source, out: list) -> None:
        # Drain the current generation before following a move, so nothing written there is lost.
        for _ in range(2):
            ring = src.ring
            head = ring.head
            if head - src.cursor > ring.slot_count:
                self.dropped += head - ring.slot_count - src.cursor
                src.cursor = head - ring.slot_count
            while src.cursor < head:
                status, buf, stamp = src.read(src.cursor)
                if status == R.OK and buf is not None:
                    out.append((stamp, buf, src.publisher_id))
                    src.cursor += 1
                elif status == R.LAPPED:
                    self.dropped += 1
                    src.cursor += 1
                else:
                    break  # a writer died mid-message: nothing after it exists yet
            if not ring.moved_to:
                return
            self._follow(src)

    def has_news(self) -> bool:
        """Whether a publisher we know has written past our cursor (cheap: for spin loops)."""
        for src in self.sources.values():
            q = src.ring.q
            if q[R._HEAD] > src.cursor or q[R._MOVED_PID] & 0xFFFFFFFF:
                return True
        return False

    def take(self) -> list[Any]:
        """Every new message, decoded, oldest first (at most ``queue_size``)."""
        return [codec.decode(self.msg_cls, buf) for _, buf, _ in self.take_raw()]

    def take_with_info(self) -> list[tuple[Any, int, str]]:
        return [(codec.decode(self.msg_cls, buf), stamp, pub) for stamp, buf, pub in self.take_raw()]

    def latest_raw(self) -> tuple[int, Any, str] | None:
        """The newest message across publishers, skipping any backlog."""
        self.rescan()
        best: tuple[int, Any, str] | None = None
        for src in self.sources.values():
            self._follow(src)
            ring = src.ring
            # The newest slot may belong to a writer that died mid-copy; the one before it is
            # then the newest complete message.
            for n in (ring.head - 1, ring.head - 2):
                if n < max(src.cursor, ring.first):
                    break
                status, buf, stamp = src.read(n)
                if status == R.OK and buf is not None:
                    src.cursor = n + 1
                    if best is None or stamp > best[0]:
                        best = (stamp, buf, src.publisher_id)
                    break
                if status == R.LAPPED:
                    break
        return best

    def latest(self) -> Any | None:
        item = self.latest_raw()
        return None if item is None else codec.decode(self.msg_cls, item[1])

    def publishers(self) -> list[str]:
        self.rescan()
        return sorted(self.sources)

    def close(self) -> None:
        for src in self.sources.values():
            if self.waker is not None:
                try:
                    src.ring.remove_waiter(self.waker.token)
                except (OSError, ValueError, TypeError):
                    pass
            src.close()
        self.sources.clear()
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
        topic, pub, _ = parsed
        ring = R.Ring.attach(name)
        if ring is None:
            continue
        entry = topics.setdefault(topic, {"type": ring.type_name, "publishers": []})
        if pub not in entry["publishers"]:
            entry["publishers"].append(pub)
        ring.close()
    subs_dir = ctx.run_dir / "subs"
    if subs_dir.is_dir():
        for folder in subs_dir.iterdir():
            info = topics.setdefault(decode_name(folder.name), {"type": "?", "publishers": []})
            info["subscribers"] = len(list(folder.iterdir()))
    return topics


def iter_segments(ctx: RunContext) -> Iterator[Path]:
    for name in ctx.all_segments():
        yield SHM_DIR / name
