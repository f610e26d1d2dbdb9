"""Detour references around obstacles that block the path ahead.

Sampling controllers scored against a path that runs through an obstacle sit in a local
minimum in front of it: the path term and the goal term both point at the obstacle, the
obstacle term pushes back. Here the blocked stretch of the reference is pushed sideways, one
side for the whole stretch, just far enough for the robot to fit, ramping in before it, so
the path term itself leads around the obstacle.
"""
from __future__ import annotations

import numpy as np

from .clearance import nearby_obstacles

__all__ = ["free_points", "detour_reference"]


def free_points(points: np.ndarray, obstacles: np.ndarray, clearance: float) -> np.ndarray:
    """Whether each point (N, 2) is farther than ``clearance`` from every obstacle (M, 2)."""
    if obstacles.shape[0] == 0:
        return np.ones(points.shape[0], dtype=bool)
    p = np.asarray(points, dtype=np.float32)
    o = np.asarray(obstacles, dtype=np.float32)
    dx = p[:, 0:1] - o[None, :, 0]
    dy = p[:, 1:2] - o[None, :, 1]
    dx *= dx
    dy *= dy
    dx += dy
    return dx.min(axis=1) > np.float32(clearance * clearance)


def detour_reference(points: np.ndarray, yaw: np.ndarray, s: np.ndarray, horizon: int,
                     obstacles: np.ndarray, radius: float, margin: float,
                     prefer_side: float) -> tuple[np.ndarray, float]:
    """Reference for the next ``horizon`` points of ``points`` (an extended look-ahead).

    ``points``/``yaw``/``s`` (arc length) describe the path from the robot onwards, longer
    than ``horizon`` so that the end of a blockage can be found. Returns the reference
    polyline (the first ``horizon`` points if nothing blocks them) and the side used
    (+1 left, -1 right), which callers feed back as ``prefer_side`` to avoid dithering.
    """
    seg = points[:horizon]
    if obstacles.shape[0] == 0 or points.shape[0] < 2:
        return seg, prefer_side
    near = nearby_obstacles(obstacles, points[0], float(s[-1] - s[0]) + radius + 0.1)
    if near.shape[0] == 0:
        return seg, prefer_side
    needed = radius + margin + 0.05
    free = free_points(points, near, needed)
    if np.all(free[:horizon]):
        return seg, prefer_side
    first_blocked = int(np.argmin(free[:horizon]))
    after = np.nonzero(free[first_blocked:])[0]
    end = first_blocked + int(after[0]) if after.size else points.shape[0] - 1
    seg = points[: end + 1].copy()
    blocked = ~free[: end + 1]
    normal_all = np.stack([-np.sin(yaw[: end + 1]), np.cos(yaw[: end + 1])], axis=-1)
    normal = normal_all[blocked]
    shifts = np.arange(1, 41) * 0.05
    need: dict[float, float] = {}
    for side in (1.0, -1.0):
        cand = seg[blocked][:, None, :] + side * shifts[None, :, None] * normal[:, None, :]
        ok = free_points(cand.reshape(-1, 2), near, needed).reshape(cand.shape[:2])
        if np.all(ok.any(axis=1)):
            need[side] = float(shifts[np.argmax(ok, axis=1)].max())
    if not need:  # no way around within 2 m: track up to the blockage only
        return seg[: max(first_blocked, 1)], prefer_side
    # Keep the side chosen before unless it became clearly worse.
    side = min(need, key=lambda sd: need[sd] - (0.25 if sd == prefer_side else 0.0))
    s_all = s[: end + 1]
    s_block = s_all[blocked]
    ramp = 2.0 * radius + 0.5
    gap = np.maximum(s_block.min() - s_all, 0.0) + np.maximum(s_all - s_block.max(), 0.0)
    weight = np.where(blocked, 1.0, np.clip(1.0 - gap / ramp, 0.0, 1.0))
    seg += (side * need[side] * weight)[:, None] * normal_all
    ok = free_points(seg, near, radius + margin)
    return (seg[ok] if np.count_nonzero(ok) >= 2 else seg), side
