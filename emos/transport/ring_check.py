"""Consistency checks of a ring segment: its header before any field is used (every reader and
writer, at attach), and its message map and slot headers (a writer re-opening its ring after a
restart). See ``ring.py`` for the layout and the seqlock protocol these checks follow."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from emos.transport.ring import Ring

# ``ring`` imports this module; these functions import it back when called (not on a hot path).


def header_problem(u64: np.ndarray, size: int, generation: int | None = None) -> str | None:
    """What is inconsistent in a ring header (``u64``: its first words; ``size``: the segment's
    bytes), or ``None``. Every geometry field is implied by depth and capacity, so they are
    recomputed rather than trusted: after this, no slot offset can point outside the segment."""
    from emos.transport import ring as R

    geom = int(u64[R._GEOM])
    depth, gen = geom & 0xFFFFFFFF, geom >> 32
    if not 1 <= depth <= R.MAX_DEPTH:
        return f"depth {depth} is outside 1..{R.MAX_DEPTH}"
    if generation is not None and gen != generation:
        return f"header says generation {gen}, its name says {generation}"
    capacity, stride = int(u64[R._CAPACITY]), int(u64[R._STRIDE])
    if not 64 <= capacity <= R._MAX_CAPACITY or capacity % 64:
        return f"slot capacity {capacity} B is not a multiple of 64 in 64..{R._MAX_CAPACITY}"
    if stride != R._align(R.SLOT_HEADER + capacity, 64):
        return f"slot stride {stride} B does not match capacity {capacity} B"
    if int(u64[R._SLOTS]) != depth + R.LOAN_ENTRIES:
        return f"{int(u64[R._SLOTS])} physical slots for depth {depth} (expected {depth + R.LOAN_ENTRIES})"
    data_offset = R._align(R._MAP_IDX * 8 + 8 * depth, R.MIN_HEADER)
    if int(u64[R._DATA_OFF]) != data_offset:
        return f"slot 0 at byte {int(u64[R._DATA_OFF])}, expected {data_offset}"
    if data_offset + stride * (depth + R.LOAN_ENTRIES) > size:
        return f"{depth + R.LOAN_ENTRIES} slots of {stride} B do not fit in {size} B"
    first, head = int(u64[R._FIRST]), int(u64[R._HEAD])
    if not first <= head < R._MAX_HEAD:
        return f"first message {first} and head {head} are out of order or range"
    return None


def damage(ring: Ring) -> str | None:
    """What is wrong with the message map and slot headers, or ``None`` if they hold together.

    For a writer re-opening its ring after a restart: O(depth), not for the hot path. It
    accepts every state a writer killed at any point of ``begin``/``commit`` leaves behind.
    """
    from emos.transport import ring as R

    q = ring.q
    head, first, depth = q[R._HEAD], q[R._FIRST], ring.depth
    if q[R._MOVED_PID] & 0xFFFFFFFF:
        return f"says it moved to generation {q[R._MOVED_PID] & 0xFFFFFFFF}"
    used: set[int] = set()
    for i in range(depth):
        entry = q[R._MAP_IDX + i]
        held, slot = entry >> 16, entry & 0xFFFF
        if slot >= ring.physical_slots:
            return f"message map entry {i} points at slot {slot} of {ring.physical_slots}"
        if held == R._EMPTY:
            # Empty is fine only if no kept message number falls on this entry.
            window_start = max(first, head - depth)
            if (i - window_start) % depth < head - window_start:
                return f"message map entry {i} is empty, but message numbers up to {head - 1} were written"
            continue
        # A killed writer may have stored the map entry of message ``head`` but not head.
        if held % depth != i or not max(first, head - depth) <= held <= head:
            return f"message map entry {i} holds message {held}, outside {max(first, head - depth)}..{head}"
        idx = ring.slot_index(slot)
        seq = q[idx]
        # Complete, or being (re)written with message ``head`` by a writer that was killed.
        if seq not in (2 * held + 2, 2 * head + 1, 2 * head + 2):
            if seq and held < (seq - 1) // 2 < head:
                # Stale: a recent-slot write gave the slot a newer message (ring.py), or began to
                # and was killed, and the restarted writer wrote that number elsewhere.
                continue
            return f"slot {slot} has sequence {seq}, expected {2 * held + 2} for message {held}"
        if seq == 2 * held + 2:  # a killed writer's slot may still be named by a stale entry too
            if slot in used:
                return f"message map entry {i} shares slot {slot} with another entry"
            used.add(slot)
        if q[idx + 1] > ring.capacity:
            return f"slot {slot} claims {q[idx + 1]} B, slots hold {ring.capacity} B"
    if head > first and (q[R._MAP_IDX + (head - 1) % depth] >> 16) not in (head - 1, head):
        return f"message {head - 1} (the newest) is not in the message map"
    return None
