"""Shapes to an occupancy grid: the bridge from a simulated world to a ROS map of it.

A cell is occupied when its centre lies inside a shape's footprint (every footprint is a convex
polygon). The demo house's shipped map is generated this way from the same shapes the
simulator builds, so a plan on the map matches the walls the robot meets.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .primitives import Shape


def _inside_convex(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Which of ``points`` (N, 2) lie inside the convex ``polygon`` (K, 2, either winding)."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    edge = b - a  # (K, 2)
    rel = points[:, None, :] - a[None, :, :]  # (N, K, 2)
    cross = edge[None, :, 0] * rel[:, :, 1] - edge[None, :, 1] * rel[:, :, 0]
    return np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)


def shapes_to_grid(shapes: Sequence[Shape], resolution: float, origin: tuple[float, float],
                   size: tuple[int, int]) -> np.ndarray:
    """(rows, cols) bool grid, row 0 at the bottom (the ROS map convention in memory):
    True where a cell centre is inside a shape. ``origin`` is the world (x, y) of the
    bottom-left corner of cell (0, 0); ``size`` is (rows, cols)."""
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"shapes_to_grid: resolution must be > 0 m, got {resolution!r}")
    rows, cols = int(size[0]), int(size[1])
    if rows < 1 or cols < 1:
        raise ValueError(f"shapes_to_grid: size must be >= 1 x 1 cells, got {size!r}")
    grid = np.zeros((rows, cols), dtype=bool)
    ox, oy = origin
    for shape in shapes:
        poly = shape.footprint()
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        c0 = max(int(math.floor((lo[0] - ox) / resolution)), 0)
        c1 = min(int(math.ceil((hi[0] - ox) / resolution)), cols)
        r0 = max(int(math.floor((lo[1] - oy) / resolution)), 0)
        r1 = min(int(math.ceil((hi[1] - oy) / resolution)), rows)
        if c0 >= c1 or r0 >= r1:
            continue
        cc, rr = np.meshgrid(np.arange(c0, c1), np.arange(r0, r1))
        centres = np.c_[ox + (cc.ravel() + 0.5) * resolution, oy + (rr.ravel() + 0.5) * resolution]
        hit = _inside_convex(centres, poly).reshape(cc.shape)
        grid[r0:r1, c0:c1] |= hit
    return grid
