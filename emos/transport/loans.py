"""Zero-copy reads: a subscriber's loans on one ring.

A loan hands the subscriber a read-only numpy view of a message in the publisher's ring instead
of a copy, and pins that slot so the writer writes elsewhere meanwhile (see ``ring.py``). The
loan lasts exactly as long as the view: decoded arrays are views of it and keep it alive, and
when the last of them is garbage collected a weak-reference callback unpins the slot. Keeping a
message (in a list, as a component's latest input) keeps its loan; a subscriber that has used
up its pin entries receives copies until one is returned, so holding on to messages never stalls
the publisher nor blocks delivery.
"""
from __future__ import annotations

import weakref
from functools import partial

import numpy as np

from emos.transport import ring as R

LOANS_PER_SUBSCRIBER = 2
# Below this a copy is cheaper than a loan's bookkeeping (a fence, a weak reference: ~2 us).
LOAN_MIN_BYTES = 16 * 1024


class LoanBook:
    """The pin entries one subscriber claimed on one ring, and the loans outstanding on them."""

    def __init__(self, ring: R.Ring, wanted: int = LOANS_PER_SUBSCRIBER):
        self.ring = ring
        self.table = ring.pins()
        self.entries = self.table.claim(ring.fd, wanted) if wanted > 0 else []
        self.free = list(self.entries)
        self._refs: dict[int, weakref.ref[np.ndarray]] = {}  # pin entry -> the array lent on it
        self.closed = False

    @property
    def outstanding(self) -> int:
        return len(self._refs)

    def loan(self, n: int) -> tuple[int, np.ndarray | None, int] | None:
        """Message ``n`` as a pinned view, or ``None`` when every entry is lent (copy instead)."""
        if not self.free:
            return None
        entry = self.free.pop()
        status, view, stamp = self.ring.loan(n, entry)
        if status != R.OK or view is None:
            self.free.append(entry)
            return status, None, 0
        self._refs[entry] = weakref.ref(view, partial(self._returned, entry))
        return R.OK, view, stamp

    def _returned(self, entry: int, _ref: object) -> None:
        # Runs in whichever thread dropped the last reference, possibly after close().
        self.table.release(entry)
        self._refs.pop(entry, None)
        if self.closed:
            self.table.abandon(entry)
            if not self._refs:
                self.table.close()
        else:
            self.free.append(entry)

    def close(self) -> None:
        """Give back idle entries now; entries still lent are given back when their loan ends."""
        if self.closed:
            return
        self.closed = True
        idle = [e for e in self.entries if e not in self._refs]
        if self.ring.mm is not None:
            self.table.unclaim(self.ring.fd, idle)
        self.free.clear()
        if not self._refs:
            self.table.close()
