"""A single-writer, many-reader ring of variable-size messages in one shared-memory segment.

Layout: a header (at least 4 KiB: fields, wake-up tokens, loan pins, the message map), then
``slot_count`` *physical* slots of ``slot_stride`` bytes. Each slot starts with
``seq | length | stamp_ns | reserved`` (u64 each) followed by the payload.

The ring keeps the last ``depth`` messages. The *message map* says where each lives: entry
``n % depth`` holds ``(n << 16) | slot`` for message ``n``. There are ``depth + LOAN_ENTRIES``
physical slots, so a reader may *loan* a slot (read it in place, zero-copy) and the writer
simply writes elsewhere until the loan ends.

Seqlock protocol, for message number ``n`` (0, 1, 2, ...):

* the writer picks a free slot ``p`` (not mapped to one of the other ``depth - 1`` kept
  messages, not pinned by a loan), stores ``seq = 2n+1`` (being written), copies the payload,
  stores ``seq = 2n+2`` (complete), stores the map entry, then advances ``head`` to ``n+1``;
* a copying reader looks ``n`` up in the map, reads ``seq``, copies the payload out, reads
  ``seq`` again; it accepts the copy only if both reads equal ``2n+2``;
* a loaning reader stores the slot in one of its pin entries, fences, and checks ``seq == 2n+2``.
  The writer stores ``seq = 2n+1``, fences, and checks the pins before touching the payload; if
  the slot is pinned it restores ``seq`` and picks another slot. The two fences make the classic
  store-then-load handshake (Dekker's): at least one side sees the other, so a loaned slot is
  never overwritten while the loan lasts.

Recent slots. Round-robin over ``depth`` slots makes a ping-pong of big messages cycle through
``2 * depth`` slots of two rings (160 MiB at depth 10 and 8 MiB), far beyond the caches and the
TLB; cycling two slots instead made the 8 MiB ping-pong between two components 19 % faster here
(issue 34; ``RECENT_MIN_BYTES`` says where it pays). So a writer asked to (``begin(...,
recent=True)``, a volatile topic's publisher), for a message of ``RECENT_MIN_BYTES`` or more, writes message ``n`` into the slot of message ``n - 2``
instead of that of ``n - depth``, *if every reader has read past ``n - 2``*: each reader
registered for wake-ups stores its cursor (the next number it will read) in the word beside its
token (``_CURSOR_IDX``), and readers that cannot be tracked (no wake-up token) are counted in
``_UNTRACKED``, whose being non-zero turns the reuse off. A reader that lags keeps the full
``depth`` of history; the newest message is never overwritten, so ``latest`` and a late joiner
still find it. Message ``n - 2``'s map entry then goes *stale* (it names a slot that holds a newer
message): a reader that looks it up finds ``seq`` of another number and reports LAPPED, as for
any overwritten message. The retiring entry's slot is reused only while it still holds that
message; otherwise the writer takes a slot no map entry names (``_claim_any``).

A writer killed mid-copy leaves ``seq = 2n+1``, the map and ``head`` untouched: readers see no
new message, never a torn one, and a restarted writer rewrites message ``n``. A publisher's
loaned message (``loans.PublisherLoan``) is such a copy held open while the caller fills the slot;
:meth:`Ring.abandon` gives it up in that same state.

Header word ``_BUSY`` is a hint, not part of the protocol: the time a writer expects to finish a
long copy (:meth:`Ring.announce`), so that lingering readers spin through it rather than park
(``waker.py``, "Long writes"). A stale or forged value costs a reader some spinning, bounded.

Memory order. Apart from the two handshake fences the protocol needs that the writer's stores
(``seq`` odd, payload, ``seq`` even, map entry) become visible in that order and that the
reader's loads (map entry, ``seq``, payload, ``seq``) happen in that order. x86-64 guarantees
both (total store order), except for non-temporal stores, which a publisher uses to copy big
arrays into a slot (``codec.STREAM_MIN_BYTES``): that copy (``_ccodec.stream_copy``) is bracketed
by store fences, so it too lands after ``seq = 2n+1`` and before the commit. On weakly ordered CPUs
(arm64) ``WEAK_ORDERING`` adds a full fence at each step that needs one (see ``commit`` and
``read``); docs/runtime.md gives the argument.

Small messages in C. ``emos/msgs/_ccodec.c`` (``ring_publish``, ``ring_take``) does what
:meth:`Ring.begin`, the copy and :meth:`Ring.commit` do, and what :meth:`Ring.read` does, in one
call per small message (publisher) or per batch of them (subscriber), with the same stores, loads
and fences in the same order and the same checks of every word it reads from the segment;
this module gives it its layout at import (``RING_C``, at the end). It handles only the common
case (the retiring slot is free, frames up to ``pubsub.SMALL_FRAME_BYTES``, messages below the
loan threshold) and leaves everything else to the code here, with the ring untouched. A big
message's loan is one C call too (``ring_loan``, what :meth:`Ring.loan` does; the loan book
calls it and falls back to :meth:`Ring.loan` for anything it does not take). A change to this
protocol must be made there too (tests/runtime/test_small_message_path.py,
tests/ipc_loan/test_loan_c_path.py).

Trust. A segment is opened only through :func:`emos.transport.trust.open_owned` (a regular file
of our uid, mode 0600, no symbolic link), its header is checked for consistency before any
field is used, and every index read from shared memory afterwards (a slot number from the map,
a payload length) is checked before it is used: a ring that fails raises :class:`RingCorrupt`,
never an ``IndexError`` from deep inside, so a subscriber can drop it and carry on.

A message bigger than a slot *grows* the ring: the writer creates generation ``g+1`` with
larger slots and records it in the old header's ``moved_to``; readers follow.
"""
from __future__ import annotations

import fcntl
import mmap
import os
import time
from pathlib import Path

import numpy as np

from emos.errors import TransportError
from emos.msgs import codec
from emos.transport import ring_check
from emos.transport.context import SHM_DIR
from emos.transport.fence import WEAK_ORDERING, full_fence
from emos.transport.trust import SEGMENT_MODE, open_owned

MAGIC = 0x34474E52534F4D45  # b"EMOSRNG4" little-endian
MIN_HEADER = 4096
SLOT_HEADER = 32
MAX_WAITERS = 64
LOAN_ENTRIES = 8  # pin entries per ring: loans outstanding at once, across all its readers
MAX_DEPTH = 0xFFFF - LOAN_ENTRIES  # physical slots are numbered in 16 bits in the message map
# Messages at least this big may go to a recent slot (module doc, "Recent slots"). Measured in the
# component ping-pong on this VM (1 MiB of L2 per core): 8 MiB 19 % faster at p50 and 30 % at p99,
# 2 MiB 0-20 % faster; but 921,600 B and 1.5 MiB 10-16 % slower: a slot that fits the reader's L2
# is still there when it comes round again, and the writer's streaming stores must first take its
# lines from that core, which a slot ``depth`` messages old no longer costs.
RECENT_MIN_BYTES = 2 * 1024 * 1024
# Header fields as u64 indices.
_MAGIC, _GEOM, _STRIDE, _CAPACITY, _HEAD, _MOVED_PID, _WAITERS_VER, _FIRST, _CREATED = range(9)
_FINGERPRINT_OFF = 80  # 16 ascii bytes
_TYPE_OFF = 96  # 128 utf-8 bytes
_SLOTS, _DATA_OFF = 28, 29  # physical slot count; byte offset of slot 0
# CLOCK_MONOTONIC ns until which the writer expects to be copying message ``head`` (0: not
# writing): a hint for lingering readers (see ``announce``), never trusted for correctness.
_BUSY = 30
# How many readers of this ring the writer cannot track (no cursor word: a subscriber without a
# wake-up token); while not 0, no recent-slot reuse (module doc). Changed under the ring's lock.
_UNTRACKED = 31
_WAITERS_IDX = 256 // 8  # MAX_WAITERS u64 tokens
_PIN_OWNER_IDX = 768 // 8  # LOAN_ENTRIES u64: pid of the reader that claimed the entry, or 0
_PIN_IDX = _PIN_OWNER_IDX + LOAN_ENTRIES  # LOAN_ENTRIES u64: loaned slot + 1, or 0
# MAX_WAITERS u64, beside each token: the first message number owed to that subscriber (the
# head when it was registered), so one that attaches after a publish still gets that message.
_MARK_IDX = 1024 // 8
# MAX_WAITERS u64, beside each token: that reader's cursor, the next message number it will read
# (0 until it says: "not caught up"), for recent-slot reuse (module doc).
_CURSOR_IDX = 1536 // 8
_MAP_IDX = 2048 // 8  # depth u64 map entries
_EMPTY = (1 << 48) - 1  # the message number of a map entry that holds nothing yet
_MAX_HEAD = 1 << 47  # message numbers live in 48 bits of a map entry, _EMPTY excluded
_MAX_CAPACITY = 1 << 40

# Status of reading one message number.
NOT_READY = 0  # not written yet, or being written
LAPPED = 1  # overwritten by a newer message (the reader fell more than a ring behind)
OK = 2
CORRUPT = 3  # not a status ``read`` returns: a caller's name for a message that raised RingCorrupt

class RingError(TransportError, RuntimeError):
    pass


class MessageTooLarge(RingError, ValueError):
    """A message exceeds the largest size a slot (a ring) or a topic (a publisher's limit) accepts.

    The one class for both: a ring raises it for a slot too small, a publisher for a message
    over the topic's limit. ValueError is kept for callers of ``Publisher.publish`` that caught it
    before the two were one class."""


class RingCorrupt(RingError):
    """A segment whose header, message map or slot headers are inconsistent (damaged or forged)."""


class TypeMismatch(RingError):
    pass


def _align(n: int, a: int = 64) -> int:
    return (n + a - 1) // a * a


class Ring:
    """One generation of a ring. Writers use :meth:`create`/:meth:`write`; readers :meth:`attach`/:meth:`read`."""

    def __init__(self, name: str, fd: int, mm: mmap.mmap):
        """Wrap a mapped segment whose header ``ring_check.header_problem`` accepted (or that we created)."""
        self.name = name
        self.fd = fd
        self.mm = mm
        self.u64 = np.frombuffer(mm, dtype=np.uint64)  # for table operations (waiters)
        self.view = memoryview(mm)
        self.q = self.view.cast("Q")  # u64 fields on the hot path: ~3x cheaper than numpy scalars
        geom = int(self.u64[_GEOM])
        self.depth = geom & 0xFFFFFFFF
        self.generation = geom >> 32
        self.stride = int(self.u64[_STRIDE])
        self.capacity = int(self.u64[_CAPACITY])
        self.physical_slots = int(self.u64[_SLOTS])
        self.data_offset = int(self.u64[_DATA_OFF])
        self.fingerprint = bytes(mm[_FINGERPRINT_OFF : _FINGERPRINT_OFF + 16]).decode("ascii", "replace")
        self.type_name = bytes(mm[_TYPE_OFF : _TYPE_OFF + 128]).rstrip(b"\0").decode("utf-8", "replace")
        self._pending_slot = -1  # writer: the slot claimed by begin(), filled in by commit()
        self._readers: list[int] = []  # writer: cursor word indices of the registered readers...
        self._readers_version = -1  # ...as of this waiters-table version

    @property
    def slot_count(self) -> int:
        """How many messages the ring keeps (its depth)."""
        return self.depth

    # -- lifecycle -------------------------------------------------------------------------------
    @classmethod
    def create(cls, name: str, slot_count: int, capacity: int, fingerprint: str, type_name: str, generation: int = 0, first: int = 0) -> Ring:
        """A new segment keeping ``slot_count`` messages of up to ``capacity`` bytes."""
        if not 1 <= slot_count <= MAX_DEPTH:
            raise ValueError(f"ring {name}: depth (slot_count) must be in 1..{MAX_DEPTH}, got {slot_count}")
        capacity = _align(max(capacity, 64), 64)
        stride = _align(SLOT_HEADER + capacity, 64)
        physical = slot_count + LOAN_ENTRIES
        data_offset = _align(_MAP_IDX * 8 + 8 * slot_count, MIN_HEADER)
        size = data_offset + stride * physical
        path = SHM_DIR / name
        # O_EXCL: never adopt a file someone else put under this name (FileExistsError instead).
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC, SEGMENT_MODE)
        try:
            os.fchmod(fd, SEGMENT_MODE)  # exactly: readers refuse any other mode, whatever our umask
            os.ftruncate(fd, size)
            mm = mmap.mmap(fd, size)
        except BaseException:
            os.close(fd)
            os.unlink(path)
            raise
        u64 = np.frombuffer(mm, dtype=np.uint64)
        u64[_GEOM] = (generation << 32) | slot_count
        u64[_STRIDE] = stride
        u64[_CAPACITY] = capacity
        u64[_SLOTS] = physical
        u64[_DATA_OFF] = data_offset
        u64[_HEAD] = first
        u64[_FIRST] = first
        u64[_CREATED] = time.monotonic_ns()  # CLOCK_MONOTONIC: one clock for every process, never steps
        mm[_FINGERPRINT_OFF : _FINGERPRINT_OFF + 16] = fingerprint.encode()[:16].ljust(16, b"\0")
        mm[_TYPE_OFF : _TYPE_OFF + 128] = type_name.encode()[:128].ljust(128, b"\0")
        # Map entry i starts out empty and pointing at slot i: the writer fills slots 0..depth-1
        # in turn, as a plain ring would; the LOAN_ENTRIES spare slots are used only around loans.
        u64[_MAP_IDX : _MAP_IDX + slot_count] = (np.uint64(_EMPTY) << np.uint64(16)) | np.arange(slot_count, dtype=np.uint64)
        u64[_MAGIC] = MAGIC  # last: readers ignore a segment until it is fully initialised
        del u64
        return cls(name, fd, mm)

    @classmethod
    def attach(cls, name: str, generation: int | None = None) -> Ring | None:
        """Open an existing segment of ours; ``None`` if it vanished or is not initialised yet.

        Raises :class:`~emos.transport.trust.UntrustedFile` for a file that is not ours and
        :class:`RingCorrupt` for a header that does not hold together (or whose generation is
        not ``generation``, the one its name gives).
        """
        try:
            fd = open_owned(SHM_DIR / name)
        except FileNotFoundError:
            return None
        try:
            size = os.fstat(fd).st_size
            if size == 0:
                os.close(fd)
                return None  # just created, not sized yet
            if size < MIN_HEADER:
                raise RingCorrupt(f"ring {name}: {size} B is too small for a header")
            mm = mmap.mmap(fd, size)
        except BaseException:
            os.close(fd)
            raise
        u64 = np.frombuffer(mm, dtype=np.uint64, count=_MAP_IDX)
        magic = int(u64[_MAGIC])
        problem = None if magic == MAGIC else "" if magic == 0 else f"bad magic {magic:#x}"
        if problem is None:
            problem = ring_check.header_problem(u64, size, generation)
        del u64
        if problem is not None:
            mm.close()
            os.close(fd)
            if problem == "":
                return None  # the creator has not finished (magic is written last)
            raise RingCorrupt(f"ring {name}: {problem}")
        return cls(name, fd, mm)

    def close(self) -> None:
        if self.mm is None:
            return
        self.q.release()
        self.view.release()
        self.u64 = None  # type: ignore[assignment]
        try:
            self.mm.close()
        except BufferError:
            # A message still references this mapping (a loan, or a view kept by its owner);
            # the mapping is freed when that message is garbage collected.
            pass
        self.mm = None  # type: ignore[assignment]
        os.close(self.fd)

    @property
    def unlinked(self) -> bool:
        """Whether the segment's name is gone (the writer removed it); we may still read it."""
        return os.fstat(self.fd).st_nlink == 0

    def unlink(self) -> None:
        try:
            os.unlink(SHM_DIR / self.name)
        except FileNotFoundError:
            pass

    # -- header ----------------------------------------------------------------------------------
    @property
    def head(self) -> int:
        return self.q[_HEAD]

    @property
    def first(self) -> int:
        return self.q[_FIRST]

    @property
    def moved_to(self) -> int:
        return self.q[_MOVED_PID] & 0xFFFFFFFF

    def set_moved_to(self, generation: int) -> None:
        self.u64[_MOVED_PID] = (self.writer_pid << 32) | generation

    @property
    def writer_pid(self) -> int:
        return int(self.u64[_MOVED_PID]) >> 32

    def set_writer_pid(self, pid: int) -> None:
        self.u64[_MOVED_PID] = (pid << 32) | self.moved_to

    def slot_index(self, slot: int) -> int:
        """u64 index of a physical slot's header."""
        return (self.data_offset + slot * self.stride) >> 3

    def slot_of(self, n: int) -> int | None:
        """The physical slot the map gives message ``n``, or ``None`` if it holds another one."""
        status, slot = self._locate(n)
        return slot if status == OK else None

    def _corrupt(self, what: str) -> RingCorrupt:
        return RingCorrupt(f"ring {self.name}: {what}")

    # -- writing ---------------------------------------------------------------------------------
    def begin(self, nbytes: int, recent: bool = False) -> tuple[int, memoryview]:
        """Claim the next message number and a free slot; returns the number and the payload buffer to fill.

        ``recent``: for a message of ``RECENT_MIN_BYTES`` or more, reuse the slot of message
        ``n - 2`` when every reader has read it (module doc, "Recent slots")."""
        if nbytes > self.capacity:
            raise MessageTooLarge(f"{nbytes} B > slot capacity {self.capacity} B")
        q = self.q
        n = q[_HEAD]
        slot = -1
        if recent and nbytes >= RECENT_MIN_BYTES and self.depth > 2 and n >= 2:
            slot = self._recent_slot(n)
        if slot < 0:
            # The slot of the message this one retires, while it still holds it (a recent-slot
            # write may have given it a newer message) and no reader holds it.
            entry = q[_MAP_IDX + n % self.depth]
            slot = entry & 0xFFFF
            if slot >= self.physical_slots or not self._claim(slot, n, entry >> 16):
                slot = self._claim_any(n)
        self._pending_slot = slot
        off = self.data_offset + slot * self.stride + SLOT_HEADER
        return n, self.view[off : off + nbytes]

    def _recent_slot(self, n: int) -> int:
        """The slot of message ``n - 2``, claimed for message ``n``, if every reader has read
        past it and none holds it; else -1 (module doc, "Recent slots")."""
        q = self.q
        if q[_UNTRACKED]:
            return -1
        if q[_WAITERS_VER] != self._readers_version:
            self._readers_version = q[_WAITERS_VER]
            self._readers = [_CURSOR_IDX + i for i, token in enumerate(q[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS].tolist()) if token]
        for idx in self._readers:
            if q[idx] < n - 1:
                return -1  # a reader has yet to read message n - 2 (or has not said): keep it
        entry = q[_MAP_IDX + (n - 2) % self.depth]
        slot = entry & 0xFFFF
        if entry >> 16 != n - 2 or slot >= self.physical_slots or q[self.slot_index(slot)] != 2 * n - 2:
            return -1
        return slot if self._claim(slot, n) else -1

    def _claim(self, slot: int, n: int, retiring: int = -1) -> bool:
        """Mark ``slot`` as being written with message ``n`` unless a loan pins it. ``retiring``:
        the message the slot should hold (``_EMPTY``: none yet); refused if it holds a newer
        one, which a recent-slot write put there (module doc)."""
        q = self.q
        idx = self.slot_index(slot)
        before = q[idx]
        if retiring >= 0 and before and before != 2 * retiring + 2 and before != 2 * n + 1:
            return False
        q[idx] = 2 * n + 1
        full_fence()  # our store above must be visible before we look at the pins (see module doc)
        if slot + 1 in q[_PIN_IDX : _PIN_IDX + LOAN_ENTRIES].tolist():
            q[idx] = before  # untouched: the loaning reader keeps a valid message
            return False
        return True

    def _claim_any(self, n: int) -> int:
        q = self.q
        k = n % self.depth
        mapped = {q[_MAP_IDX + i] & 0xFFFF for i in range(self.depth) if i != k}
        while True:
            pinned = {p - 1 for p in q[_PIN_IDX : _PIN_IDX + LOAN_ENTRIES].tolist() if p}
            # depth - 1 mapped + at most LOAN_ENTRIES pinned < depth + LOAN_ENTRIES slots: one is free.
            for slot in range(self.physical_slots):
                if slot not in mapped and slot not in pinned and self._claim(slot, n):
                    return slot
            # Only a pin that appeared between our look and our claim gets here; look again.

    def commit(self, n: int, nbytes: int, stamp_ns: int) -> None:
        q = self.q
        slot = self._pending_slot
        idx = self.slot_index(slot)
        q[idx + 1] = nbytes
        q[idx + 2] = stamp_ns
        if WEAK_ORDERING:
            full_fence()  # payload, length and stamp before the seq that vouches for them
        q[idx] = 2 * n + 2  # complete
        if WEAK_ORDERING:
            full_fence()  # seq before the map entry: a reader following the map must find it even
        q[_MAP_IDX + n % self.depth] = (n << 16) | slot
        # The map entry and head need no fence: a reader that sees head first finds the entry
        # not there yet, reports NOT_READY and looks again; nothing is lost or torn.
        q[_HEAD] = n + 1
        if q[_BUSY]:
            q[_BUSY] = 0
        self._pending_slot = -1

    def pending_offset(self) -> int:
        """Byte offset in the segment of the payload claimed by :meth:`begin` (a loaned message)."""
        if self._pending_slot < 0:
            raise RingError(f"ring {self.name}: no message is being written")
        return self.data_offset + self._pending_slot * self.stride + SLOT_HEADER

    def announce(self, until_ns: int) -> None:
        """Say that the message about to be written (the publisher announces before it claims
        the slot) should be complete by ``until_ns`` (``time.monotonic_ns``): a reader that
        lingers for messages keeps spinning until then instead of parking in the middle of a
        long copy (``waker.Waker.serve``).
        Only a hint: a writer killed mid-copy leaves a deadline that simply passes."""
        self.q[_BUSY] = until_ns

    @property
    def busy_until(self) -> int:
        """The writer's :meth:`announce` deadline for the message in progress, or 0."""
        return self.q[_BUSY]

    def abandon(self) -> None:
        """Give up the message claimed by :meth:`begin` without publishing it.

        Its slot is left as a writer killed mid-copy leaves it (``seq`` odd, map entry and
        ``head`` untouched): readers never see it, and the next :meth:`begin` reuses its number.
        """
        if self._pending_slot >= 0:
            self.q[_BUSY] = 0
            self._pending_slot = -1

    def write(self, payload: bytes | memoryview, stamp_ns: int | None = None) -> int:
        n, buf = self.begin(len(payload))
        buf[:] = payload
        buf.release()
        self.commit(n, len(payload), time.time_ns() if stamp_ns is None else stamp_ns)
        return n

    # -- reading ---------------------------------------------------------------------------------
    def _locate(self, n: int) -> tuple[int, int]:
        """``(status, slot)`` of message ``n`` by the map; status OK means "look at the slot"."""
        entry = self.q[_MAP_IDX + n % self.depth]
        held = entry >> 16
        if held == n:
            slot = entry & 0xFFFF
            if slot >= self.physical_slots:
                raise self._corrupt(f"message map entry {n % self.depth} points at slot {slot} of {self.physical_slots}")
            return OK, slot
        if n < self.q[_FIRST]:
            return LAPPED, -1
        return (NOT_READY if held == _EMPTY or held < n else LAPPED), -1

    def read(self, n: int) -> tuple[int, bytearray | None, int]:
        """Copy out message ``n``: ``(OK, payload, stamp_ns)``, ``(NOT_READY, None, 0)`` or ``(LAPPED, None, 0)``."""
        status, slot = self._locate(n)
        if status != OK:
            return status, None, 0
        q = self.q
        idx = self.slot_index(slot)
        want = 2 * n + 2
        if WEAK_ORDERING:
            full_fence()  # the map entry before seq (see commit)
        if q[idx] != want:
            return LAPPED, None, 0  # the slot was reused after we looked at the map
        if WEAK_ORDERING:
            full_fence()  # seq before the length, stamp and payload it vouches for
        length = q[idx + 1]
        stamp = q[idx + 2]
        start = (idx << 3) + SLOT_HEADER
        # bytearray(slice) is one malloc + memcpy; bytearray(n) then a slice assignment costs
        # a page fault per 4 KiB on large frames (calloc hands out fresh zero pages).
        buf = bytearray(self.view[start : start + min(length, self.capacity)])
        if WEAK_ORDERING:
            full_fence()  # the copy before the second look at seq
        if q[idx] != want:
            return LAPPED, None, 0
        if length > self.capacity:
            # seq held still around the copy, so the writer did not write this: damaged.
            raise self._corrupt(f"message {n} in slot {slot} claims {length} B, slots hold {self.capacity} B")
        return OK, buf, stamp

    def length_of(self, n: int) -> int:
        """Payload size of message ``n`` if the map still has it, else 0 (a hint: checked by the read)."""
        status, slot = self._locate(n)
        return self.q[self.slot_index(slot) + 1] if status == OK else 0

    def loan(self, n: int, entry: int) -> tuple[int, np.ndarray | None, int]:
        """Pin message ``n`` through pin ``entry`` and return a read-only view of its payload.

        ``(OK, view, stamp_ns)``: the writer will not touch the slot until :meth:`release`.
        Otherwise ``(NOT_READY | LAPPED, None, 0)`` and the entry is free again.
        """
        status, slot = self._locate(n)
        if status != OK:
            return status, None, 0
        q = self.q
        q[_PIN_IDX + entry] = slot + 1
        full_fence()  # the pin must be visible before we check seq (see module doc)
        idx = self.slot_index(slot)
        seq = q[idx]
        if WEAK_ORDERING:
            full_fence()  # seq before the length and payload it vouches for
        length = q[idx + 1]
        if seq != 2 * n + 2:
            q[_PIN_IDX + entry] = 0
            return LAPPED, None, 0
        if length > self.capacity:  # pinned and complete, so the writer did not write this
            q[_PIN_IDX + entry] = 0
            raise self._corrupt(f"message {n} in slot {slot} claims {length} B, slots hold {self.capacity} B")
        view = np.frombuffer(self.mm, dtype=np.uint8, count=length, offset=(idx << 3) + SLOT_HEADER)
        view.flags.writeable = False  # other readers share these bytes
        return OK, view, q[idx + 2]

    def pins(self) -> PinTable:
        """The pin entries, through a mapping of their own that outlives :meth:`close`."""
        return PinTable(self.mm)

    def stamp_of(self, n: int) -> int | None:
        status, slot = self._locate(n)
        if status != OK:
            return None
        idx = self.slot_index(slot)
        return self.q[idx + 2] if self.q[idx] == 2 * n + 2 else None

    # -- wake-up registrations ---------------------------------------------------------------------
    def _locked(self) -> _Flock:
        return _Flock(self.fd)

    def waiters(self) -> tuple[int, list[int]]:
        """``(version, tokens)`` of registered wake-up FIFOs."""
        version = int(self.u64[_WAITERS_VER])
        tokens = [int(t) for t in self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS] if t]
        return version, tokens

    @property
    def waiters_version(self) -> int:
        return self.q[_WAITERS_VER]

    def add_waiter(self, token: int, mark: int | None = None) -> bool:
        """Register a wake-up token, owed every message from ``mark`` on (default: the next one).

        A token already registered keeps its mark. ``False`` if the table is full.
        """
        with self._locked():
            table = self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS]
            if (table == token).any():
                return True
            free = np.flatnonzero(table == 0)
            if not len(free):
                return False
            self.u64[_MARK_IDX + free[0]] = self.q[_HEAD] if mark is None else mark
            self.u64[_CURSOR_IDX + free[0]] = 0  # "not caught up" until the reader says (before the token: x86 keeps the order)
            table[free[0]] = token
            self.u64[_WAITERS_VER] += 1
            return True

    def mark_of(self, token: int) -> int | None:
        """The first message number owed to ``token`` (see :meth:`add_waiter`), if registered."""
        with self._locked():
            hit = np.flatnonzero(self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS] == token)
            return int(self.u64[_MARK_IDX + hit[0]]) if len(hit) else None

    def cursor_index(self, token: int) -> int | None:
        """The u64 index of the cursor word of registered reader ``token`` (module doc), or None."""
        with self._locked():
            hit = np.flatnonzero(self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS] == token)
            return _CURSOR_IDX + int(hit[0]) if len(hit) else None

    def add_untracked(self, count: int) -> None:
        """Count ``count`` more (or, negative, fewer) readers whose cursor the writer cannot see:
        while any are counted, no recent-slot reuse (module doc). Never below 0."""
        with self._locked():
            self.u64[_UNTRACKED] = max(int(self.u64[_UNTRACKED]) + count, 0)

    @property
    def untracked(self) -> int:
        return self.q[_UNTRACKED]

    def waiter_marks(self) -> dict[int, int]:
        """``{token: mark}`` of every registered token (for carrying them to a new generation)."""
        with self._locked():
            tokens = self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS]
            return {int(t): int(self.u64[_MARK_IDX + i]) for i, t in enumerate(tokens) if t}

    def remove_waiter(self, token: int) -> None:
        with self._locked():
            table = self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS]
            hit = table == token
            if hit.any():
                table[hit] = 0
                self.u64[_WAITERS_VER] += 1

    def damage(self) -> str | None:
        """What is wrong with the message map and slot headers, or ``None`` (see :mod:`ring_check`)."""
        return ring_check.damage(self)


class PinTable:
    """A reader's handle on a ring's pin entries: claim entries, release pins.

    Entries are claimed under the ring's lock and stamped with the reader's pid, so the entries
    of a reader that died can be taken over; a dead reader's pins keep their slots out of the
    writer's way until then, which costs spare slots, never correctness.
    """

    def __init__(self, mm: mmap.mmap):
        self._q = memoryview(mm).cast("Q")

    def claim(self, fd: int, wanted: int) -> list[int]:
        """Up to ``wanted`` free pin entries for this process (fewer, or none, if taken)."""
        got: list[int] = []
        me = os.getpid()
        with _Flock(fd):
            for entry in range(LOAN_ENTRIES):
                if len(got) == wanted:
                    break
                owner = self._q[_PIN_OWNER_IDX + entry]
                if 0 < owner < 1 << 31 and _alive(owner):  # anything else is no live pid
                    continue
                self._q[_PIN_IDX + entry] = 0  # a dead reader's pin, if any, ends here
                self._q[_PIN_OWNER_IDX + entry] = me
                got.append(entry)
        return got

    def unclaim(self, fd: int, entries: list[int]) -> None:
        with _Flock(fd):
            for entry in entries:
                if self._q[_PIN_OWNER_IDX + entry] == os.getpid():
                    self._q[_PIN_OWNER_IDX + entry] = 0

    def release(self, entry: int) -> None:
        """End the loan held through ``entry``. Safe from any thread, after the ring closed."""
        self._q[_PIN_IDX + entry] = 0

    def abandon(self, entry: int) -> None:
        """Give ``entry`` back without the lock (its reader closed; a claimer sees 0 or our pid)."""
        self._q[_PIN_OWNER_IDX + entry] = 0

    def held(self, entry: int) -> int:
        """The slot pinned through ``entry`` plus one, or 0."""
        return self._q[_PIN_IDX + entry]

    def close(self) -> None:
        self._q.release()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class _Flock:
    def __init__(self, fd: int):
        self.fd = fd

    def __enter__(self) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_EX)

    def __exit__(self, *exc: object) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_UN)


def segment_exists(name: str) -> bool:
    return (SHM_DIR / name).exists()


def segment_path(name: str) -> Path:
    return SHM_DIR / name


# The C fast path of this protocol (module doc, "Small messages in C"), told this module's header
# layout once; None without the C codec, with EMOS_CODEC=python, or with a build older than this
# layout (no ring_write: its ring_layout takes fewer words), which then runs the Python path.
RING_C = codec.C_CODEC if hasattr(codec.C_CODEC, "ring_write") else None
if RING_C is not None:
    RING_C.ring_layout(_HEAD, _FIRST, _BUSY, _MAP_IDX, _PIN_IDX, LOAN_ENTRIES, SLOT_HEADER, _MAX_HEAD, _EMPTY, _UNTRACKED, _WAITERS_IDX,
                       _CURSOR_IDX, MAX_WAITERS)
