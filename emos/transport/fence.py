"""A full memory barrier for protocols between processes sharing memory, which Python lacks."""
from __future__ import annotations

import platform
import threading

_FENCE_LOCK = threading.Lock()

# Total store order (x86): stores are seen in program order, and so are loads; only a store
# followed by a load may be reordered. Any other CPU (arm64, POWER, RISC-V) may also reorder two
# stores or two loads, which the seqlock in ``ring.py`` must then forbid with fences.
_TOTAL_STORE_ORDER = {"x86_64", "amd64", "i386", "i486", "i586", "i686", "x86"}
WEAK_ORDERING: bool = platform.machine().lower() not in _TOTAL_STORE_ORDER


def full_fence() -> None:
    """Order every store before this call against every load after it (about 0.2 us).

    Seqlocks need only program order, but store-then-load handshakes (a reader pinning a slot,
    a subscriber parking) need a full barrier on both sides, and x86-64 itself reorders a store
    with a later load. An uncontended lock acquire and release are atomic read-modify-writes on
    the lock word: ``lock cmpxchg`` / ``lock xadd`` on x86-64, which are full barriers; acquire
    and release operations on arm64, where a release followed by an acquire orders everything
    before it against everything after it, which two rounds guarantee.
    """
    _FENCE_LOCK.acquire()
    _FENCE_LOCK.release()
    _FENCE_LOCK.acquire()
    _FENCE_LOCK.release()
