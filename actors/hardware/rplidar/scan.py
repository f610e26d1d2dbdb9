"""Revolutions from RPLIDAR nodes, and their LaserScan arrays in the ROS convention.

The RPLIDAR's angle grows clockwise seen from above, 0 deg = the device's heading (protocol
document, Fig. 4-6). ROS (REP 103) bearings grow counter-clockwise about +z from +x (the
heading). So a node at ``theta`` degrees clockwise is at ``-theta`` in ROS: we publish
``angle_min = -pi`` and ``bins`` beams ``2 pi / bins`` apart counter-clockwise, beam i at
``-pi + i * 2 pi / bins``; each node goes to the beam nearest its converted bearing, the nearest
return wins when two share a beam, and a beam no node hit (or only invalid ones, distance 0)
is ``inf`` (no return). Intensities are the quality byte (0..63).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .protocol import ANGLE_Q6_FULL, NodeParser, Nodes

__all__ = ["Revolution", "RevolutionAssembler", "RevolutionStream", "revolution_ranges"]


@dataclass(frozen=True)
class Revolution:
    """One 360 deg scan: the nodes from one start flag (S=1) to the node before the next."""

    nodes: Nodes
    clean: bool  # no byte was dropped and no sync lost while it was read


class RevolutionAssembler:
    """Cuts a node stream into revolutions on the start flag. Nodes before the first start flag
    are a partial revolution and are discarded. ``mark_dirty()`` tells it bytes were dropped: the
    revolution being read then comes out with ``clean=False``."""

    def __init__(self, max_nodes: int = 8192) -> None:
        self.max_nodes = max_nodes  # a stream that never raises S again must not grow memory
        self._parts: list[Nodes] = []
        self._count = 0
        self._started = False
        self._dirty = False

    def reset(self) -> None:
        self._parts, self._count, self._started, self._dirty = [], 0, False, False

    def mark_dirty(self) -> None:
        self._dirty = True

    def feed(self, nodes: Nodes) -> list[Revolution]:
        out: list[Revolution] = []
        if not len(nodes):
            return out
        starts = np.flatnonzero(nodes.start)
        cuts = [0, *starts.tolist(), len(nodes)]
        for a, b in zip(cuts[:-1], cuts[1:]):
            if a == b:
                continue
            piece = Nodes(nodes.start[a:b], nodes.quality[a:b], nodes.angle_q6[a:b], nodes.distance_q2[a:b])
            if nodes.start[a]:  # a new revolution begins: the one in hand is complete
                if self._started and self._count:
                    out.append(Revolution(Nodes.concat(self._parts), clean=not self._dirty))
                self._parts, self._count, self._started, self._dirty = [], 0, True, False
            if not self._started:
                continue  # before the first start flag
            self._parts.append(piece)
            self._count += len(piece)
            if self._count > self.max_nodes:
                self.reset()
        return out


class RevolutionStream:
    """Bytes of a SCAN session -> revolutions: a :class:`~.protocol.NodeParser` and a
    :class:`RevolutionAssembler`, with every dropped byte marking the revolution being read
    dirty (the driver delivers only clean ones: a slip the parser detected may have cost or
    bent a node next to it)."""

    def __init__(self) -> None:
        self.parser = NodeParser(hold_until_start=True)  # revolutions need no node before the next start flag
        self.assembler = RevolutionAssembler()

    def feed(self, data: bytes) -> list[Revolution]:
        nodes = self.parser.feed(data)
        marks = self.parser.drop_marks
        if not marks:
            return self.assembler.feed(nodes)
        # A slip may have cost or bent the nodes on either side of it: the revolution that holds
        # the node before it and the one that holds the node after it are both dirty.
        asm, out, prev = self.assembler, [], 0
        for m in marks:
            if m >= prev:
                out += asm.feed(nodes[prev:m])
                asm.mark_dirty()
                out += asm.feed(nodes[m:m + 1])
                prev = m + 1
            asm.mark_dirty()
        out += asm.feed(nodes[prev:])
        return out


def revolution_ranges(nodes: Nodes, bins: int, range_min: float, range_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(ranges in m, intensities) on ``bins`` beams from -pi counter-clockwise (module docstring)."""
    ranges = np.full(bins, np.inf, dtype=np.float32)
    intens = np.zeros(bins, dtype=np.float32)
    r = nodes.distance_q2.astype(np.float32) / np.float32(4000.0)  # q2 mm -> m
    ok = (nodes.distance_q2 > 0) & (r >= range_min) & (r <= range_max)
    # ROS bearing = -theta (clockwise -> counter-clockwise); beam i sits at -pi + i * 2pi/bins, so
    # i = round((pi - theta) * bins / 2pi) = round(bins/2 - angle_q6 * bins / (360 * 64))
    idx = np.rint(bins / 2.0 - nodes.angle_q6[ok] * (bins / ANGLE_Q6_FULL)).astype(np.int64) % bins
    rr = r[ok]
    np.minimum.at(ranges, idx, rr)  # the nearest return wins a shared beam
    win = ranges[idx] == rr
    intens[idx[win]] = nodes.quality[ok][win]
    return ranges, intens
