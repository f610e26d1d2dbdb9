"""The likelihood-field sensor model (Probabilistic Robotics, table 6.3; Nav2's
``LikelihoodFieldModel``), vectorised over particles and beams.

A beam's end point is scored by its distance ``d`` to the nearest occupied cell of the map:

    p(z) = z_hit * exp(-d^2 / (2 sigma_hit^2)) + z_rand / laser_max_range

with ``d`` capped at ``laser_likelihood_max_dist`` (an end point outside the map scores the cap,
as in Nav2). The distances come from one Euclidean distance transform of the occupied cells
(scipy.ndimage through ``maps.edt``), made when the map is set.

Lookup (``interpolation``): ``"bilinear"`` (default) interpolates ``d`` between the four
nearest cell centres, then scores it; ``"nearest"`` (Nav2's) reads the tabulated score of the
cell the end point falls in. Nearest quantises ``d`` to the cell: an end point anywhere in a
wall-adjacent cell scores as if it sat on the cell's centre, so the likelihood is a staircase
in the pose, flat over a cell (5 cm) and blind to where inside it the pose is; interpolated,
it is continuous, and the filter and the estimate's polish resolve the pose below a cell.
Bilinear costs four gathers and an exp/log per beam and particle instead of one gather.

A particle's log-likelihood is the sum over the beams it uses (at most ``max_beams``, spread
evenly over the valid ones: finite, above ``laser_min_range``, below ``laser_max_range``). Nav2
sums cubes of p(z) instead (a heuristic to flatten the posterior); the sum of logs is the model
itself and keeps the estimate as sharp as the map allows.
"""
from __future__ import annotations

import math

import numpy as np

from ..maps.edt import euclidean_distance_transform
from ..maps.grid import OccupancyGridMap

__all__ = ["LikelihoodField", "select_beams", "OCCUPIED_THRESHOLD", "FREE_THRESHOLD"]

#: Map cells at or above this occupancy (0..100) are obstacles (map_server's occupied_thresh 0.65).
OCCUPIED_THRESHOLD = 65
#: Known cells at or below this occupancy are free space (map_server's free_thresh 0.25).
FREE_THRESHOLD = 25


def select_beams(ranges: np.ndarray, angles: np.ndarray, max_beams: int, range_min: float,
                 range_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(ranges, angles) of at most ``max_beams`` valid beams, evenly spread over the valid ones.
    NaN, inf, zero or negative readings, and readings outside [range_min, range_max) are not
    valid (a max-range reading is "no echo": it says nothing about where walls are)."""
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    ok = np.isfinite(r) & np.isfinite(a) & (r > max(range_min, 0.0)) & (r < range_max)
    idx = np.flatnonzero(ok)
    if len(idx) > max_beams > 0:
        idx = idx[np.linspace(0, len(idx) - 1, max_beams).round().astype(np.int64)]
    return r[idx], a[idx]


class LikelihoodField:
    """Log-likelihood of scans for many poses against one map (see the module docstring)."""

    def __init__(self, grid: OccupancyGridMap, *, sigma_hit: float, z_hit: float, z_rand: float,
                 max_dist: float, laser_max_range: float, interpolation: str = "bilinear") -> None:
        if interpolation not in ("bilinear", "nearest"):
            raise ValueError(f"LikelihoodField: interpolation must be 'bilinear' or 'nearest', got {interpolation!r}")
        self.interpolation = interpolation
        self.grid = grid
        self.resolution = float(grid.resolution)
        data = np.asarray(grid.data)
        occupied = data >= OCCUPIED_THRESHOLD
        self.free_cells = np.argwhere((data >= 0) & (data <= FREE_THRESHOLD))  # (row, col)
        self.has_obstacles = bool(occupied.any())
        dist = euclidean_distance_transform(occupied, sampling=self.resolution) if self.has_obstacles \
            else np.full(data.shape, np.inf)
        dist = np.minimum(dist, max_dist)
        rand = z_rand / laser_max_range if math.isfinite(laser_max_range) and laser_max_range > 0 else 0.0
        # One extra cell (the last, flat index h*w) holds the score of an end point off the map.
        table = z_hit * np.exp(-(dist * dist) / (2.0 * sigma_hit * sigma_hit)) + rand
        off_map = z_hit * math.exp(-(max_dist * max_dist) / (2.0 * sigma_hit * sigma_hit)) + rand
        table = np.append(table.reshape(-1), off_map)
        self.log_table = np.log(np.maximum(table, 1e-300))
        # For bilinear lookup: the distances with a one-cell border at the cap, so that the four
        # neighbours of any end point within half a cell of the map exist (beyond: the cap).
        self._dist_padded = np.pad(dist, 1, constant_values=max_dist).astype(np.float64)
        self._dist_flat = self._dist_padded.ravel()
        self._max_dist = float(max_dist)
        self._z_hit, self._rand = float(z_hit), float(rand)
        self._inv_2s2 = 1.0 / (2.0 * sigma_hit * sigma_hit)
        self.shape = data.shape
        # For through_walls: occupied cells, flat, with one extra False for points off the map.
        self._occupied_flat = np.append(occupied.reshape(-1), False)
        ox, oy, oyaw = grid.origin
        self._origin = (float(ox), float(oy), float(oyaw))

    def to_map_frame(self, poses: np.ndarray) -> np.ndarray:
        """World poses (N, 3) in the frame of the grid's origin corner (metres, rad)."""
        ox, oy, oyaw = self._origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        dx, dy = poses[:, 0] - ox, poses[:, 1] - oy
        return np.stack([c * dx + s * dy, -s * dx + c * dy, poses[:, 2] - oyaw], axis=-1)

    def log_likelihood(self, poses: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
                       sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0), chunk: int = 4096) -> np.ndarray:
        """Sum over the beams of log p(z), for each pose (N,). Beams must be pre-selected."""
        n = len(poses)
        out = np.zeros(n)
        if len(ranges) == 0 or n == 0:
            return out
        sx, sy, syaw = sensor_pose
        # Beam end points in the robot frame (B, 2).
        bx = sx + ranges * np.cos(syaw + angles)
        by = sy + ranges * np.sin(syaw + angles)
        m = self.to_map_frame(np.asarray(poses, dtype=np.float64))
        h, w = self.shape
        inv = 1.0 / self.resolution
        off = h * w
        if self.interpolation == "bilinear":
            for lo in range(0, n, chunk):
                out[lo : lo + chunk] = self._bilinear(m[lo : lo + chunk], bx, by, inv)
            return out
        for lo in range(0, n, chunk):
            p = m[lo : lo + chunk]
            c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
            col = np.floor((p[:, 0:1] + c * bx - s * by) * inv)
            row = np.floor((p[:, 1:2] + s * bx + c * by) * inv)
            inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
            flat = np.where(inside, row * w + col, off).astype(np.int64)
            out[lo : lo + chunk] = self.log_table[flat].sum(axis=1)
        return out

    def _bilinear(self, p: np.ndarray, bx: np.ndarray, by: np.ndarray, inv: float) -> np.ndarray:
        """Sum over beams of log p(z) with ``d`` interpolated between cell centres, for the
        map-frame poses ``p`` (n, 3) and robot-frame end points ``bx``, ``by`` (B,)."""
        h, w = self.shape
        c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
        # Continuous index in the padded grid: cell centres at integers (+1 for the border).
        fx = (p[:, 0:1] + c * bx - s * by) * inv + 0.5
        fy = (p[:, 1:2] + s * bx + c * by) * inv + 0.5
        i0 = np.floor(fx)
        j0 = np.floor(fy)
        inside = (i0 >= 0) & (i0 <= w) & (j0 >= 0) & (j0 <= h)
        tx = fx - i0
        ty = fy - j0
        # One flat index per end point into the padded grid (row-major), its three neighbours
        # at +1, +W, +W+1: a quarter of the index arithmetic of four 2-D lookups, and the
        # interpolation updated in place (this is most of the filter's CPU time).
        wp = w + 2
        k = np.where(inside, j0 * wp + i0, 0).astype(np.int64)
        dp = self._dist_flat
        d00 = dp[k]
        d01 = dp[k + 1]
        d10 = dp[k + wp]
        d11 = dp[k + (wp + 1)]
        d = d00 + tx * (d01 - d00)
        d += ty * ((d10 + tx * (d11 - d10)) - d)
        d[~inside] = self._max_dist
        d *= d
        d *= -self._inv_2s2
        ll = np.log(np.maximum(self._z_hit * np.exp(d) + self._rand, 1e-300))
        return np.asarray(ll.sum(axis=1), dtype=np.float64)

    def through_walls(self, poses: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
                      sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0), margin: float = 0.3) -> np.ndarray:
        """For each pose (N,), how many beams pass through an occupied cell before ``margin``
        metres short of their end point: what the likelihood field cannot see (it scores only
        where a beam ends), and what tells a look-alike place from the robot's: a wall the beam
        would have had to cross. Beams are sampled every cell along their length."""
        n = len(poses)
        if n == 0 or len(ranges) == 0 or not self.has_obstacles:
            return np.zeros(n, dtype=np.int64)
        step = self.resolution
        reach = np.maximum(np.asarray(ranges, dtype=np.float64) - margin, 0.0)
        k = int(math.ceil(float(reach.max()) / step)) if reach.max() > 0 else 0
        if k == 0:
            return np.zeros(n, dtype=np.int64)
        dist = step * np.arange(1, k + 1)  # (K,) sample distances along a beam
        valid = dist[None, :] <= reach[:, None]  # (B, K)
        sx, sy, syaw = sensor_pose
        px = sx + dist[None, :] * np.cos(syaw + angles)[:, None]  # (B, K), robot frame
        py = sy + dist[None, :] * np.sin(syaw + angles)[:, None]
        m = self.to_map_frame(np.asarray(poses, dtype=np.float64))
        h, w = self.shape
        inv = 1.0 / self.resolution
        out = np.zeros(n, dtype=np.int64)
        for i in range(n):  # a few poses (the search's hypotheses): (B, K) each
            c, s_ = math.cos(m[i, 2]), math.sin(m[i, 2])
            col = np.floor((m[i, 0] + c * px - s_ * py) * inv)
            row = np.floor((m[i, 1] + s_ * px + c * py) * inv)
            inside = valid & (col >= 0) & (col < w) & (row >= 0) & (row < h)
            flat = np.where(inside, row * w + col, h * w).astype(np.int64)
            out[i] = int(self._occupied_flat[flat].any(axis=1).sum())
        return out
