"""Correlative scan matching against the navigator's own obstacle memory.

Wheel odometry drifts; a map built from scans placed with it smears obstacles into copies
that close real gaps. Before a scan is added, the matcher searches a small window of poses
around the odometry guess for the one under which the scan's hits best fall on obstacles
already in memory (a likelihood field: Gaussian of the distance to the nearest remembered
hit), and the navigator keeps the map <- odometry correction that this implies.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..maps.edt import euclidean_distance_transform
from .hit_grid import HitGrid


def compose(correction: np.ndarray | Sequence[float], pose: np.ndarray | Sequence[float]) -> np.ndarray:
    """SE(2) ``correction`` applied to ``pose`` (both x, y, yaw)."""
    tx, ty, tt = correction
    c, s = math.cos(tt), math.sin(tt)
    return np.array([tx + c * pose[0] - s * pose[1], ty + s * pose[0] + c * pose[1], pose[2] + tt])


def correction_between(map_pose: np.ndarray, odom_pose: np.ndarray) -> np.ndarray:
    """The correction T with ``compose(T, odom_pose) == map_pose``."""
    tt = map_pose[2] - odom_pose[2]
    c, s = math.cos(tt), math.sin(tt)
    return np.array([map_pose[0] - (c * odom_pose[0] - s * odom_pose[1]),
                     map_pose[1] - (s * odom_pose[0] + c * odom_pose[1]), tt])


class ScanMatcher:
    def __init__(self, search_xy: float = 0.12, step_xy: float = 0.02, search_yaw: float = 0.06,
                 step_yaw: float = 0.01, sigma: float = 0.04, max_points: int = 200, min_map_cells: int = 60) -> None:
        self.dxy = np.arange(-search_xy, search_xy + 1e-9, step_xy)
        self.dyaw = np.arange(-search_yaw, search_yaw + 1e-9, step_yaw)
        self.sigma, self.max_points, self.min_map_cells = sigma, max_points, min_map_cells
        self._field: np.ndarray | None = None
        self._field_version = -1

    def _likelihood(self, grid: HitGrid) -> np.ndarray:
        """The likelihood field of ``grid`` behind a border of zeros: cell (r, c) is at
        (r + 1, c + 1) and index 0 of either axis reads 0 (outside the window)."""
        if self._field is None or self._field_version != grid.version:
            dist = euclidean_distance_transform(grid.occupied, grid.resolution)
            field = np.zeros((grid.shape[0] + 1, grid.shape[1] + 1), dtype=np.float32)
            field[1:, 1:] = np.exp(-0.5 * (dist / self.sigma) ** 2)
            self._field, self._field_version = field, grid.version
        return self._field

    def match(self, grid: HitGrid, guess: np.ndarray, points_local: np.ndarray) -> tuple[np.ndarray, float, float]:
        """Best pose near ``guess`` for scan hits ``points_local`` (N, 2, robot frame).

        Returns (pose, score at the best pose, score at the guess), scores in [0, 1] (mean
        likelihood of the hits). With too little map or too few hits, returns the guess.
        """
        guess = np.asarray(guess, dtype=float)
        if len(points_local) < 20 or np.count_nonzero(grid.occupied) < self.min_map_cells:
            return guess, 0.0, 0.0
        pts = points_local[:: max(1, len(points_local) // self.max_points)]
        field = self._likelihood(grid)
        yaws = guess[2] + self.dyaw
        c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        # Hits rotated by every candidate heading (Y, N).
        rx = c * pts[:, 0] - s * pts[:, 1] + guess[0]
        ry = s * pts[:, 0] + c * pts[:, 1] + guess[1]
        # A candidate (heading, dx, dy) puts a hit in the column of its x shift and the row of
        # its y shift, so cells are computed per (heading, shift, hit), for x and y apart (Y*X*N
        # each), and only the gather is Y*X*X*N: a third of the time of shifting every point in
        # both axes, for the same cells. Cells outside the window read the field's zero border.
        h, w = grid.shape
        cols = np.floor((rx[:, None, :] + self.dxy[None, :, None] - grid.origin[0]) / grid.resolution).astype(np.int64)
        rows = np.floor((ry[:, None, :] + self.dxy[None, :, None] - grid.origin[1]) / grid.resolution).astype(np.int64)
        cols = np.where((cols >= 0) & (cols < w), cols + 1, 0)
        rows = np.where((rows >= 0) & (rows < h), rows + 1, 0)
        score = field[rows[:, None, :, :], cols[:, :, None, :]].mean(axis=-1)  # (Y, X, Y')
        # Prefer the guess on ties: odometry is right over short distances.
        prior = 1.0 - 0.02 * (np.abs(self.dyaw)[:, None, None] / max(self.dyaw.max(), 1e-9)
                              + (np.abs(self.dxy)[None, :, None] + np.abs(self.dxy)[None, None, :]) / max(self.dxy.max(), 1e-9))
        best = np.unravel_index(int(np.argmax(score * prior)), score.shape)
        k0 = len(self.dyaw) // 2, len(self.dxy) // 2, len(self.dxy) // 2
        pose = np.array([guess[0] + self.dxy[best[1]], guess[1] + self.dxy[best[2]], yaws[best[0]]])
        return pose, float(score[best]), float(score[k0])
