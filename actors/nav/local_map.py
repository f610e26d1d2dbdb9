"""Rolling, ego-centric occupancy grid from a LaserScan by raycasting.

The grid is centred on the robot and aligned with its frame; every scan rebuilds it: cells a
beam passes through are free (0), the cell where it ends is occupied (100), all others stay
unknown (-1). A beam with no return (``inf``) frees its whole length up to ``range_max`` (or
the map edge); NaN beams carry no information and are skipped.

Two equivalent tracers, both vectorized over all beams:

* ``update`` (fast path) turns raycasting around: for every cell, cached per scan geometry,
  it knows its distance from the sensor and which beam passes through it (the beam nearest
  in angle, if within the cell's angular half-width; otherwise no beam crosses the cell).
  A scan update is then one gather and a comparison per cell: O(cells), independent of how
  many beams overlap near the robot (3,600 beams share most cells within a few metres).
* ``trace_rays`` samples every beam every half cell, laid out in one flat array; O(total
  traced length). It is the direct formulation, kept to cross-check the fast path.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from .controllers.base import in_range, setters
from .controllers.sensors import LaserScan2D

__all__ = ["MapConfig", "MapperConfig", "LocalMapper", "FREE", "OCCUPIED", "UNKNOWN"]

FREE, OCCUPIED, UNKNOWN = 0, 100, -1


@attrs.define
class MapConfig:
    """Local map size (m) and resolution (m/cell)."""

    width: float = attrs.field(default=3.0, converter=float, validator=in_range(1e-2, 1e3), on_setattr=setters)
    height: float = attrs.field(default=3.0, converter=float, validator=in_range(1e-2, 1e3), on_setattr=setters)
    resolution: float = attrs.field(default=0.05, converter=float, validator=in_range(1e-3, 10.0), on_setattr=setters)

    def __attrs_post_init__(self) -> None:
        if self.width / self.resolution > 20_000 or self.height / self.resolution > 20_000:
            raise ValueError(f"MapConfig: {self.width} x {self.height} m at {self.resolution} m/cell "
                             f"is over 20,000 cells per side; use a coarser resolution")

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) = (height, width) in cells."""
        return int(round(self.height / self.resolution)), int(round(self.width / self.resolution))


MapperConfig = MapConfig  # the name the spec's usage example uses


class LocalMapper:
    """Builds the ego-centric grid. ``origin`` is the robot-frame (x, y) of cell (0, 0)'s corner.

    With ``keep_memory`` and a robot pose (odom frame) given to :meth:`update`, the previous
    grid rolls along with the robot: cells the new scan says nothing about keep what was seen
    before (e.g. obstacles that left a narrow field of view), cells it observes are replaced
    (so a beam through a stale obstacle frees it), and cells that leave the window are dropped.
    """

    def __init__(self, config: MapConfig | None = None,
                 sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 keep_memory: bool = False) -> None:
        self.config = config or MapConfig()
        self.sensor_pose = sensor_pose
        self.keep_memory = keep_memory
        self._last_pose: np.ndarray | None = None
        rows, cols = self.config.shape
        self.origin = (-0.5 * cols * self.config.resolution, -0.5 * rows * self.config.resolution)
        self.grid = np.full((rows, cols), UNKNOWN, dtype=np.int8)
        # Per scan layout: (beam index per cell, distance per cell); see _cell_beams.
        self._cache_key: tuple | None = None
        self._cache: tuple[np.ndarray, np.ndarray] = (np.zeros(0, np.int32), np.zeros(0, np.float32))

    def _beam_lengths(self, scan: LaserScan2D) -> tuple[np.ndarray, np.ndarray]:
        """Free length of each beam (0 for NaN/too-short beams) and the mask of real hits."""
        cfg = self.config
        r = scan.ranges
        usable = ~np.isnan(r)
        hit = usable & scan.valid_mask()
        # Beams without a return free their full length (bounded by the map diagonal).
        limit = min(scan.range_max, math.hypot(cfg.width, cfg.height))
        no_return = usable & (np.isinf(r) | (r > scan.range_max))
        length = np.where(hit, r, np.where(no_return, limit, 0.0))
        return length, hit

    def _mark_hits(self, scan: LaserScan2D, hit: np.ndarray) -> None:
        cfg = self.config
        rows, cols = cfg.shape
        if not np.any(hit):
            return
        sx, sy, syaw = self.sensor_pose
        r = scan.ranges[hit]
        ang = scan.beam_angles()[hit] + syaw
        col = np.floor((sx + r * np.cos(ang) - self.origin[0]) / cfg.resolution).astype(np.int64)
        row = np.floor((sy + r * np.sin(ang) - self.origin[1]) / cfg.resolution).astype(np.int64)
        inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        self.grid[row[inside], col[inside]] = OCCUPIED

    def _cell_beams(self, scan: LaserScan2D) -> tuple[np.ndarray, np.ndarray]:
        """Per cell: index of the beam crossing it (-1: none) and distance to the sensor."""
        angles = scan.beam_angles()
        key = (angles.size, float(angles[0]) if angles.size else 0.0,
               float(angles[-1]) if angles.size else 0.0, float(np.sum(angles)))
        if self._cache_key == key:
            return self._cache
        cfg = self.config
        rows, cols = cfg.shape
        res = cfg.resolution
        sx, sy, syaw = self.sensor_pose
        xc = self.origin[0] + (np.arange(cols) + 0.5) * res - sx
        yc = self.origin[1] + (np.arange(rows) + 0.5) * res - sy
        dx, dy = np.meshgrid(xc, yc)
        dist = np.hypot(dx, dy)
        cell_ang = np.arctan2(dy, dx) - syaw
        order = np.argsort(angles)
        sorted_ang = angles[order]
        wrapped = (cell_ang - sorted_ang[0]) % (2 * math.pi) + sorted_ang[0]
        j = np.clip(np.searchsorted(sorted_ang, wrapped), 1, max(angles.size - 1, 1))
        lo = sorted_ang[j - 1]
        hi = sorted_ang[np.minimum(j, angles.size - 1)]
        pick_hi = np.abs(hi - wrapped) < np.abs(wrapped - lo)
        nearest = np.where(pick_hi, j, j - 1)
        gap = np.abs(wrapped - sorted_ang[nearest])
        gap = np.minimum(gap, 2 * math.pi - gap)
        # A beam crosses the cell if it passes within the cell's angular half-width.
        half_width = np.arctan2(0.5 * math.sqrt(2.0) * res, np.maximum(dist, 1e-9))
        beam = np.where(gap <= half_width, order[nearest], -1).astype(np.int32).reshape(-1)
        self._cache_key = key
        self._cache = (beam, dist.astype(np.float32).reshape(-1))
        return self._cache

    def update(self, scan: LaserScan2D, pose: np.ndarray | None = None) -> np.ndarray:
        """Rebuild the grid from ``scan`` and return it (int8, rows = y, cols = x).

        ``pose`` (x, y, yaw) of the robot is only needed with ``keep_memory``.
        """
        carried = self._carry(pose) if self.keep_memory else None
        self._observe(scan)
        if carried is not None:
            np.copyto(self.grid, carried, where=self.grid == UNKNOWN)
        return self.grid

    def _carry(self, pose: np.ndarray | None) -> np.ndarray | None:
        """The previous grid resampled into the frame of ``pose`` (None on the first scan)."""
        if pose is None:
            return None
        pose = np.asarray(pose, dtype=np.float64).reshape(3)
        last, self._last_pose = self._last_pose, pose
        if last is None:
            return None
        cfg = self.config
        rows, cols = cfg.shape
        res = cfg.resolution
        xc = self.origin[0] + (np.arange(cols) + 0.5) * res
        yc = self.origin[1] + (np.arange(rows) + 0.5) * res
        x, y = np.meshgrid(xc, yc)
        # Current robot frame -> world -> previous robot frame.
        c, s = math.cos(pose[2]), math.sin(pose[2])
        wx, wy = pose[0] + c * x - s * y, pose[1] + s * x + c * y
        c0, s0 = math.cos(last[2]), math.sin(last[2])
        dx, dy = wx - last[0], wy - last[1]
        px, py = c0 * dx + s0 * dy, -s0 * dx + c0 * dy
        col = np.floor((px - self.origin[0]) / res).astype(np.int64)
        row = np.floor((py - self.origin[1]) / res).astype(np.int64)
        inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        carried = np.full((rows, cols), UNKNOWN, dtype=np.int8)
        carried[inside] = self.grid[row[inside], col[inside]]
        return carried

    def _observe(self, scan: LaserScan2D) -> None:
        length, hit = self._beam_lengths(scan)
        beam, dist = self._cell_beams(scan)
        grid = self.grid.reshape(-1)
        # Free: crossed by a beam and nearer than where it ends (the end cell is not freed).
        reach = np.append(length.astype(np.float32), np.float32(0.0))[beam]  # beam -1 -> 0
        free = dist < reach - np.float32(0.5 * self.config.resolution)
        np.copyto(grid, np.where(free, np.int8(FREE), np.int8(UNKNOWN)))
        self._mark_hits(scan, hit)

    def trace_rays(self, scan: LaserScan2D) -> np.ndarray:
        """Rebuild the grid by sampling each beam every half cell (reference tracer)."""
        cfg = self.config
        rows, cols = cfg.shape
        res = cfg.resolution
        grid = self.grid
        grid.fill(UNKNOWN)
        length, hit = self._beam_lengths(scan)
        sx, sy, syaw = self.sensor_pose
        theta = (scan.beam_angles() + syaw).astype(np.float32)
        step = np.float32(0.5 * res)
        counts = np.ceil(length / step).astype(np.int64)
        total = int(counts.sum())
        if total:
            beam = np.repeat(np.arange(length.size), counts)
            starts = np.cumsum(counts) - counts
            # Sample k of each beam sits at distance k * step (k < count: the end is not freed).
            k = (np.arange(total) - np.repeat(starts, counts)).astype(np.float32) * step
            inv = np.float32(1.0 / res)
            col = ((np.float32(sx - self.origin[0]) + k * np.cos(theta)[beam]) * inv).astype(np.int32)
            row = ((np.float32(sy - self.origin[1]) + k * np.sin(theta)[beam]) * inv).astype(np.int32)
            inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
            grid.reshape(-1)[row[inside] * cols + col[inside]] = FREE
        self._mark_hits(scan, hit)
        return grid

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the robot-frame point (x, y)."""
        res = self.config.resolution
        return int(math.floor((y - self.origin[1]) / res)), int(math.floor((x - self.origin[0]) / res))
