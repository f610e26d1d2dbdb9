"""SE2 path geometry: interpolation to a spacing, length, densification for checks."""
from __future__ import annotations

import math

import numpy as np

from emos.geometry import wrap_angle

__all__ = ["wrap_angle", "path_length", "interpolate_se2"]


def path_length(path: np.ndarray) -> float:
    """Planar length (m) of an (N, 2+) path."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))))


def interpolate_se2(path: np.ndarray, max_step: float, max_yaw_step: float = math.inf) -> np.ndarray:
    """Insert poses so that consecutive poses are at most ``max_step`` metres apart in x-y and
    ``max_yaw_step`` radians apart in yaw.

    Each segment is split evenly; x, y move linearly and yaw along the shortest arc, which is
    how OMPL's SE2 state space interpolates, so the result traces the same motions the planner
    checked. The original poses are kept. Vectorized over all segments.
    """
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"interpolate_se2: expected an (N, 3) path, got shape {p.shape}")
    if not (max_step > 0 and max_yaw_step > 0):
        raise ValueError("interpolate_se2: max_step and max_yaw_step must be > 0")
    if len(p) < 2:
        return p.copy()
    d_xy = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    d_yaw = wrap_angle(np.diff(p[:, 2]))
    pieces = np.maximum(np.ceil(d_xy / max_step), 1)
    if math.isfinite(max_yaw_step):
        pieces = np.maximum(pieces, np.ceil(np.abs(d_yaw) / max_yaw_step))
    pieces = pieces.astype(np.int64)
    seg = np.repeat(np.arange(len(pieces)), pieces)
    starts = np.r_[0, np.cumsum(pieces)[:-1]]
    t = (np.arange(pieces.sum()) - np.repeat(starts, pieces)) / np.repeat(pieces, pieces)
    x = p[seg, 0] + t * (p[seg + 1, 0] - p[seg, 0])
    y = p[seg, 1] + t * (p[seg + 1, 1] - p[seg, 1])
    yaw = wrap_angle(p[seg, 2] + t * d_yaw[seg])
    out = np.empty((len(seg) + 1, 3))
    out[:-1, 0], out[:-1, 1], out[:-1, 2] = x, y, yaw
    out[-1] = p[-1]
    out[-1, 2] = wrap_angle(p[-1, 2])
    return out
