"""An obstacle memory that forgets what the lidar later sees through: occupancy with evidence
decay for cells seen free, for worlds where obstacles move.

``HitGrid`` never forgets (best for static worlds with good odometry). ``EvidenceGrid`` keeps
a small hit count per cell: each scan that ends a beam in a cell raises it (up to ``cap``),
each scan whose beam passes through the cell's exact hit point (within ``tolerance``) and
goes on lowers it, and a cell whose count reaches zero is released. A static wall keeps being
hit, so it stays; where a moving obstacle was, later beams pass, so its trail is released
after a few scans. Cells no beam reaches (behind the robot, occluded) keep what they had:
only positive evidence of free space forgets.

It also stamps every cell a beam traversed (``free_stamp``), so a tracker can ask whether a
new hit lands where the lidar recently saw free space (a sign of motion).
"""
from __future__ import annotations

import attrs
import numpy as np

from emos.config import validators as V

from .hit_grid import HitGrid

__all__ = ["EvidenceConfig", "EvidenceGrid"]


@attrs.define(frozen=True)
class EvidenceConfig:
    """How an obstacle memory forgets (``EvidenceGrid``): ``cap`` units of hit evidence a cell
    holds (scans that saw through its hit point release it after that many), ``free_range``
    (m) of each beam that counts as seeing free space (farther, a beam decays nothing)."""

    cap: int = attrs.field(default=4, validator=V.int_at_least(1))
    free_range: float = attrs.field(default=8.0, validator=V.number(gt=0, finite=True, what="a finite number of metres"))

    @classmethod
    def of(cls, value: object, owner: str) -> EvidenceConfig | None:
        """``value`` as a config: an EvidenceConfig, a dict of its fields, or None (never forget)."""
        if value is None or isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = sorted(set(value) - {a.name for a in attrs.fields(cls)})
            if unknown:
                raise ValueError(f"{owner}: unknown EvidenceConfig field(s) {unknown}; expected cap, free_range")
            return cls(**value)
        raise TypeError(f"{owner}: expected an EvidenceConfig, a dict of its fields or None, got {type(value).__name__}")


class EvidenceGrid(HitGrid):
    """``HitGrid`` with per-cell hit evidence that free-space observations decay."""

    def __init__(self, bounds: tuple[float, float, float, float], resolution: float = 0.05, cap: int = 4,
                 tolerance: float | None = None) -> None:
        super().__init__(bounds, resolution)
        if not (isinstance(cap, int) and cap >= 1):
            raise ValueError(f"EvidenceGrid.cap must be an integer >= 1, got {cap!r}")
        self.cap = cap
        # How close (m, across the beam) a beam must pass a cell's hit point to count as seeing
        # through it. Half a cell: beams are 0.375 deg apart, so at 5 m about one beam a scan
        # passes each released spot, while a beam that only grazes a surface rarely does.
        self.tolerance = 0.5 * self.resolution if tolerance is None else float(tolerance)
        self.evidence = np.zeros(self.shape, dtype=np.int16)
        self.free_stamp = np.full(self.shape, -np.inf, dtype=np.float64)
        self.since = np.full(self.shape, np.inf, dtype=np.float64)  # when a cell became occupied

    def insert(self, points: np.ndarray, stamp: float = 0.0) -> int:
        """Mark hit points (N, 2) seen at ``stamp``; each cell hit by this batch gains one unit
        of evidence."""
        if len(points) == 0:
            return 0
        rows, cols, inside = self.cell_of(points)
        flat = np.unique(rows[inside] * self.shape[1] + cols[inside])
        r, c = np.divmod(flat, self.shape[1])
        fresh = ~self.occupied[r, c]
        new = super().insert(points)
        self.since[r[fresh], c[fresh]] = stamp
        self.evidence[r, c] = np.minimum(self.evidence[r, c] + 1, self.cap)
        return new

    def moved_into(self, points: np.ndarray, stamp: float, window: float) -> np.ndarray:
        """Per point (N, 2): motion evidence. Its cell was seen free within ``window`` s before
        ``stamp`` and is not an obstacle remembered from before that (a static surface is
        neither; the ground a mover enters was free moments ago)."""
        rows, cols, inside = self.cell_of(points)
        out = np.zeros(len(rows), dtype=bool)
        r, c = rows[inside], cols[inside]
        old = self.occupied[r, c] & (self.since[r, c] < stamp - window)
        out[inside] = (self.free_stamp[r, c] >= stamp - window) & ~old
        return out

    def seen_free_since(self, points: np.ndarray, since: float) -> np.ndarray:
        """Per point (N, 2): was its cell traversed by a beam at or after ``since``?"""
        rows, cols, inside = self.cell_of(points)
        out = np.zeros(len(rows), dtype=bool)
        out[inside] = self.free_stamp[rows[inside], cols[inside]] >= since
        return out

    def observe_free(self, origin: tuple[float, float], directions: np.ndarray, lengths: np.ndarray,
                     stamp: float) -> int:
        """Beams from ``origin`` along unit ``directions`` (N, 2) saw free space for ``lengths``
        (N,) m (stop them short of their hit). Stamps the cells they cross; each occupied cell
        whose hit point they pass loses one unit of evidence (once per call) and is released
        at zero. Returns how many cells were released."""
        if len(lengths) == 0:
            return 0
        beam, rows, cols = self.cells_along(origin, directions, lengths, first=0.5 * self.resolution)
        if len(beam) == 0:
            return 0
        self.free_stamp[rows, cols] = stamp
        hit = self.occupied[rows, cols]
        if not hit.any():
            return 0
        beam, rows, cols = beam[hit], rows[hit], cols[hit]
        rel = self.hit_xy[rows, cols] - np.asarray(origin)
        d = directions[beam]
        on_beam = np.abs(d[:, 0] * rel[:, 1] - d[:, 1] * rel[:, 0]) <= self.tolerance
        before_end = (d[:, 0] * rel[:, 0] + d[:, 1] * rel[:, 1]) < lengths[beam]
        seen = on_beam & before_end
        if not seen.any():
            return 0
        flat = np.unique(rows[seen] * self.shape[1] + cols[seen])
        r, c = np.divmod(flat, self.shape[1])
        self.evidence[r, c] -= 1
        gone = self.evidence[r, c] <= 0
        if not gone.any():
            return 0
        self.evidence[r[gone], c[gone]] = 0
        self.occupied[r[gone], c[gone]] = False
        self.version += 1
        return int(np.count_nonzero(gone))
