"""An occupancy memory built from lidar hits, for a navigator that has no map."""
from __future__ import annotations

import math

import numpy as np


class HitGrid:
    """Cells of ``resolution`` metres over a fixed window; a cell is occupied once a lidar
    beam has ended in it. Each cell also keeps the exact last hit point, so collision checks
    are not blurred by the grid. Static worlds only: cells are never cleared.
    """

    def __init__(self, bounds: tuple[float, float, float, float], resolution: float = 0.05) -> None:
        xmin, ymin, xmax, ymax = bounds
        if not (xmax > xmin and ymax > ymin and resolution > 0):
            raise ValueError(f"HitGrid needs a non-empty window and resolution > 0, got {bounds!r}, {resolution!r}")
        self.origin = np.array([xmin, ymin])
        self.resolution = float(resolution)
        self.shape = (int(math.ceil((ymax - ymin) / resolution)), int(math.ceil((xmax - xmin) / resolution)))
        self.occupied = np.zeros(self.shape, dtype=bool)
        self.hit_xy = np.zeros(self.shape + (2,), dtype=float)
        # Cells a planner has closed on purpose (not seen obstacles): they block plans but
        # are not obstacle points, and can be forgotten all at once.
        self.virtual = np.zeros(self.shape, dtype=bool)
        self.virtual_xy = np.zeros(self.shape + (2,), dtype=float)
        self.version = 0  # bumps when the blocked cells change

    def cells_along(self, origin, directions: np.ndarray, lengths: np.ndarray,
                    first: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cells beams from ``origin`` along unit ``directions`` (N, 2) cross within their
        ``lengths`` (N,), sampled every cell from ``first`` m: (beam index, row, col) per sample
        inside the grid."""
        t = np.arange(first, float(np.max(lengths)), self.resolution)
        beam, step = np.nonzero(t[None, :] < lengths[:, None])
        pts = np.asarray(origin) + directions[beam] * t[step][:, None]
        rows, cols, inside = self.cell_of(pts)
        return beam[inside], rows[inside], cols[inside]

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, inside) for world points (N, 2)."""
        ij = np.floor((np.asarray(xy, dtype=float) - self.origin) / self.resolution).astype(int)
        rows, cols = ij[:, 1], ij[:, 0]
        inside = (rows >= 0) & (rows < self.shape[0]) & (cols >= 0) & (cols < self.shape[1])
        return rows, cols, inside

    def center_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return self.origin + (np.c_[cols, rows] + 0.5) * self.resolution

    def insert(self, points: np.ndarray) -> int:
        """Mark world hit points (N, 2); returns how many cells became occupied."""
        if len(points) == 0:
            return 0
        rows, cols, inside = self.cell_of(points)
        rows, cols, pts = rows[inside], cols[inside], np.asarray(points)[inside]
        fresh = ~self.occupied[rows, cols]
        new = len(np.unique(rows[fresh] * self.shape[1] + cols[fresh]))  # one batch may hit a cell twice
        self.occupied[rows, cols] = True
        self.hit_xy[rows, cols] = pts
        if new:
            self.version += 1
        return new

    def carve(self, origin: tuple[float, float], directions: np.ndarray, lengths: np.ndarray,
              tolerance: float | None = None) -> int:
        """Free-space evidence: a beam from ``origin`` along a unit direction (N, 2) that went
        on past a stored hit point, within ``tolerance`` of it (default a fifth of a cell, about
        the lidar noise), proves nothing is there any more: clear that cell. Beams passing a
        point further off may just have grazed the obstacle it belongs to, so they do not
        count. Returns how many cells were cleared. This removes ghosts left by odometry drift
        or by obstacles that moved."""
        if len(lengths) == 0 or not self.occupied.any():
            return 0
        tol = 0.2 * self.resolution if tolerance is None else tolerance
        beam, rows, cols = self.cells_along(origin, directions, lengths, first=0.0)
        if len(beam) == 0:
            return 0
        hit = self.occupied[rows, cols]
        beam, rows, cols = beam[hit], rows[hit], cols[hit]
        rel = self.hit_xy[rows, cols] - np.asarray(origin)
        d = directions[beam]
        on_beam = np.abs(d[:, 0] * rel[:, 1] - d[:, 1] * rel[:, 0]) <= tol
        before_end = (d[:, 0] * rel[:, 0] + d[:, 1] * rel[:, 1]) < lengths[beam]
        clear = on_beam & before_end
        if not clear.any():
            return 0
        r, c = rows[clear], cols[clear]
        self.occupied[r, c] = False
        self.version += 1
        return len(np.unique(r * self.shape[1] + c))

    def block(self, points: np.ndarray) -> None:
        """Mark cells as virtually blocked (for planning only)."""
        rows, cols, inside = self.cell_of(points)
        self.virtual[rows[inside], cols[inside]] = True
        self.virtual_xy[rows[inside], cols[inside]] = np.asarray(points)[inside]
        self.version += 1

    def clear_blocks(self) -> None:
        if self.virtual.any():
            self.virtual[:] = False
            self.version += 1

    def blocked(self) -> tuple[np.ndarray, np.ndarray]:
        """(cells that block plans, their exact points): seen obstacles and virtual blocks."""
        if not self.virtual.any():
            return self.occupied, self.hit_xy
        only_virtual = self.virtual & ~self.occupied
        xy = np.where(only_virtual[..., None], self.virtual_xy, self.hit_xy)
        return self.occupied | self.virtual, xy

    def points_near(self, xy: tuple[float, float], radius: float) -> np.ndarray:
        """Exact hit points of occupied cells within ``radius`` of ``xy``."""
        r = int(math.ceil(radius / self.resolution))
        (row,), (col,), _ = self.cell_of(np.array([xy]))
        r0, r1 = max(row - r, 0), min(row + r + 1, self.shape[0])
        c0, c1 = max(col - r, 0), min(col + r + 1, self.shape[1])
        if r0 >= r1 or c0 >= c1:
            return np.zeros((0, 2))
        window = self.occupied[r0:r1, c0:c1]
        pts = self.hit_xy[r0:r1, c0:c1][window]
        d2 = np.sum((pts - np.asarray(xy)) ** 2, axis=1)
        return pts[d2 <= radius * radius]
