"""A single-writer, many-reader ring of variable-size messages in one shared-memory segment.

Layout: a 4 KiB header, then ``slot_count`` slots of ``slot_stride`` bytes. Each slot starts
with ``seq | length | stamp_ns | reserved`` (u64 each) followed by the payload.

Seqlock protocol, for message number ``n`` (0, 1, 2, ...) in slot ``n % slot_count``:

* the writer stores ``seq = 2n+1`` (being written), copies the payload, stores
  ``seq = 2n+2`` (complete), then advances ``head`` to ``n+1``;
* a reader reads ``seq``, copies the payload out, reads ``seq`` again; it accepts the copy
  only if both reads equal ``2n+2``. Anything else means "not there yet" or "overwritten".

A writer killed mid-copy leaves ``seq = 2n+1`` and ``head = n``: readers see no new message,
never a torn one, and a restarted writer rewrites message ``n`` in the same slot. x86-64 keeps
stores in program order and loads in program order, which is all the protocol needs; the
interpreter's own memory fences cover weaker architectures in practice.

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

from emos.transport.context import SHM_DIR

MAGIC = 0x31474E52534F4D45  # b"EMOSRNG1" little-endian
HEADER_SIZE = 4096
SLOT_HEADER = 32
MAX_WAITERS = 64
# Header fields as u64 indices.
_MAGIC, _GEOM, _STRIDE, _CAPACITY, _HEAD, _MOVED_PID, _WAITERS_VER, _FIRST, _CREATED = range(9)
_FINGERPRINT_OFF = 80  # 16 ascii bytes
_TYPE_OFF = 96  # 128 utf-8 bytes
_WAITERS_IDX = 256 // 8  # MAX_WAITERS u64 tokens

# Status of reading one message number.
NOT_READY = 0  # not written yet, or being written
LAPPED = 1  # overwritten by a newer message (the reader fell more than a ring behind)
OK = 2


class RingError(RuntimeError):
    pass


class MessageTooLarge(RingError):
    pass


class TypeMismatch(RingError):
    pass


def _align(n: int, a: int = 64) -> int:
    return (n + a - 1) // a * a


class Ring:
    """One generation of a ring. Writers use :meth:`create`/:meth:`write`; readers :meth:`attach`/:meth:`read`."""

    def __init__(self, name: str, fd: int, mm: mmap.mmap):
        self.name = name
        self.fd = fd
        self.mm = mm
        self.u64 = np.frombuffer(mm, dtype=np.uint64)  # for table operations (waiters)
        self.view = memoryview(mm)
        self.q = self.view.cast("Q")  # u64 fields on the hot path: ~3x cheaper than numpy scalars
        geom = int(self.u64[_GEOM])
        self.slot_count = geom & 0xFFFFFFFF
        self.stride = int(self.u64[_STRIDE])
        self.capacity = int(self.u64[_CAPACITY])
        self.generation = geom >> 32
        self.fingerprint = bytes(mm[_FINGERPRINT_OFF : _FINGERPRINT_OFF + 16]).decode()
        self.type_name = bytes(mm[_TYPE_OFF : _TYPE_OFF + 128]).rstrip(b"\0").decode()

    # -- lifecycle -------------------------------------------------------------------------------
    @classmethod
    def create(cls, name: str, slot_count: int, capacity: int, fingerprint: str, type_name: str, generation: int = 0, first: int = 0) -> "Ring":
        if slot_count < 1:
            raise ValueError(f"ring {name}: slot_count must be >= 1, got {slot_count}")
        capacity = _align(max(capacity, 64), 64)
        stride = _align(SLOT_HEADER + capacity, 64)
        size = HEADER_SIZE + stride * slot_count
        path = SHM_DIR / name
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o600)
        try:
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
        u64[_HEAD] = first
        u64[_FIRST] = first
        u64[_CREATED] = time.time_ns()
        mm[_FINGERPRINT_OFF : _FINGERPRINT_OFF + 16] = fingerprint.encode()[:16].ljust(16, b"\0")
        mm[_TYPE_OFF : _TYPE_OFF + 128] = type_name.encode()[:128].ljust(128, b"\0")
        # Slots of messages before ``first`` must read as "already overwritten", not "not yet".
        for i in range(slot_count):
            u64[(HEADER_SIZE + i * stride) // 8] = 0
        u64[_MAGIC] = MAGIC  # last: readers ignore a segment until it is fully initialised
        del u64
        return cls(name, fd, mm)

    @classmethod
    def attach(cls, name: str) -> "Ring | None":
        """Open an existing segment; ``None`` if it vanished or is not initialised yet."""
        try:
            fd = os.open(SHM_DIR / name, os.O_RDWR)
        except FileNotFoundError:
            return None
        try:
            size = os.fstat(fd).st_size
            if size < HEADER_SIZE:
                os.close(fd)
                return None
            mm = mmap.mmap(fd, size)
        except (OSError, ValueError):
            os.close(fd)
            return None
        if int(np.frombuffer(mm, dtype=np.uint64, count=1)[0]) != MAGIC:
            mm.close()
            os.close(fd)
            return None
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
            # A decoded message still references this mapping (zero-copy view); the mapping is
            # freed when that message is garbage collected.
            pass
        self.mm = None  # type: ignore[assignment]
        os.close(self.fd)

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

    # -- writing ---------------------------------------------------------------------------------
    def begin(self, nbytes: int) -> tuple[int, memoryview]:
        """Claim the next message number; returns it and the payload buffer to fill."""
        if nbytes > self.capacity:
            raise MessageTooLarge(f"{nbytes} B > slot capacity {self.capacity} B")
        n = self.q[_HEAD]
        off = HEADER_SIZE + (n % self.slot_count) * self.stride
        self.q[off >> 3] = 2 * n + 1  # being written
        return n, self.view[off + SLOT_HEADER : off + SLOT_HEADER + nbytes]

    def commit(self, n: int, nbytes: int, stamp_ns: int) -> None:
        q = self.q
        idx = (HEADER_SIZE + (n % self.slot_count) * self.stride) >> 3
        q[idx + 1] = nbytes
        q[idx + 2] = stamp_ns
        q[idx] = 2 * n + 2  # complete
        q[_HEAD] = n + 1

    def write(self, payload: bytes | memoryview, stamp_ns: int | None = None) -> int:
        n, buf = self.begin(len(payload))
        buf[:] = payload
        buf.release()
        self.commit(n, len(payload), time.time_ns() if stamp_ns is None else stamp_ns)
        return n

    # -- reading ---------------------------------------------------------------------------------
    def read(self, n: int) -> tuple[int, bytearray | None, int]:
        """Copy out message ``n``: ``(OK, payload, stamp_ns)``, ``(NOT_READY, None, 0)`` or ``(LAPPED, None, 0)``."""
        off = HEADER_SIZE + (n % self.slot_count) * self.stride
        idx = off >> 3
        q = self.q
        want = 2 * n + 2
        s1 = q[idx]
        if s1 != want:
            return (NOT_READY if s1 < want else LAPPED), None, 0
        length = q[idx + 1]
        stamp = q[idx + 2]
        if length > self.capacity:
            return LAPPED, None, 0
        start = off + SLOT_HEADER
        # bytearray(slice) is one malloc + memcpy; bytearray(n) then a slice assignment costs
        # a page fault per 4 KiB on large frames (calloc hands out fresh zero pages).
        buf = bytearray(self.view[start : start + length])
        if q[idx] != want:
            return LAPPED, None, 0
        return OK, buf, stamp

    def stamp_of(self, n: int) -> int | None:
        idx = (HEADER_SIZE + (n % self.slot_count) * self.stride) // 8
        if int(self.u64[idx]) != 2 * n + 2:
            return None
        return int(self.u64[idx + 2])

    # -- wake-up registrations ---------------------------------------------------------------------
    def _locked(self) -> "_Flock":
        return _Flock(self.fd)

    def waiters(self) -> tuple[int, list[int]]:
        """``(version, tokens)`` of registered wake-up FIFOs."""
        version = int(self.u64[_WAITERS_VER])
        tokens = [int(t) for t in self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS] if t]
        return version, tokens

    @property
    def waiters_version(self) -> int:
        return self.q[_WAITERS_VER]

    def add_waiter(self, token: int) -> bool:
        with self._locked():
            table = self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS]
            if (table == token).any():
                return True
            free = np.flatnonzero(table == 0)
            if not len(free):
                return False
            table[free[0]] = token
            self.u64[_WAITERS_VER] += 1
            return True

    def remove_waiter(self, token: int) -> None:
        with self._locked():
            table = self.u64[_WAITERS_IDX : _WAITERS_IDX + MAX_WAITERS]
            hit = table == token
            if hit.any():
                table[hit] = 0
                self.u64[_WAITERS_VER] += 1


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
