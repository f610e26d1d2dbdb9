"""Reference path handling shared by the path-following controllers.

A path is resampled to a fine, uniform spacing once; the follower then keeps a *monotonic*
progress index, searched only a bounded arc length ahead of the last one. That is what makes
U-turns and closed circles (whose start and end coincide) trackable: the nearest point of the
whole path would jump between branches.
"""
from __future__ import annotations

import math

import numpy as np

from ..kinematics import wrap_angle

__all__ = ["ReferencePath", "PathProgress"]


class ReferencePath:
    """An (R, 2|3) world-frame path resampled every ``spacing`` metres, with yaw and arc length."""

    def __init__(self, path: np.ndarray, spacing: float = 0.02) -> None:
        p = np.asarray(path, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] not in (2, 3) or p.shape[0] < 1:
            raise ValueError(f"path: expected an (R, 2) or (R, 3) array of poses, got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("path: contains NaN or inf coordinates")
        if spacing <= 0:
            raise ValueError(f"spacing: expected > 0 m, got {spacing}")
        xy = p[:, :2]
        # Drop repeated points so that tangents are defined.
        keep = np.ones(len(xy), dtype=bool)
        keep[1:] = np.hypot(*np.diff(xy, axis=0).T) > 1e-9
        xy = xy[keep]
        final_yaw = float(p[-1, 2]) if p.shape[1] == 3 else None
        if len(xy) == 1:
            self.points = xy.copy()
            self.s = np.zeros(1)
            self.yaw = np.array([final_yaw if final_yaw is not None else 0.0])
        else:
            seg = np.hypot(*np.diff(xy, axis=0).T)
            s_in = np.concatenate([[0.0], np.cumsum(seg)])
            n = max(2, int(math.ceil(s_in[-1] / spacing)) + 1)
            s = np.linspace(0.0, s_in[-1], n)
            self.points = np.stack([np.interp(s, s_in, xy[:, 0]), np.interp(s, s_in, xy[:, 1])], axis=-1)
            self.s = s
            d = np.gradient(self.points, axis=0)
            self.yaw = np.arctan2(d[:, 1], d[:, 0])
        self.final_yaw = final_yaw
        self.length = float(self.s[-1])

    def __len__(self) -> int:
        return self.points.shape[0]

    def index_at(self, s: float | np.ndarray) -> np.ndarray | int:
        """Index of the resampled point at arc length ``s`` (clipped to the path)."""
        return np.clip(np.searchsorted(self.s, s), 0, len(self) - 1)

    def poses(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        sl = slice(start, stop)
        return np.column_stack([self.points[sl], self.yaw[sl]])


class PathProgress:
    """Monotonic tracking of where the robot is along a :class:`ReferencePath`."""

    def __init__(self, path: ReferencePath, search_ahead: float = 1.0) -> None:
        self.path = path
        self.index = 0
        self.search_ahead = search_ahead

    def update(self, pose: np.ndarray) -> int:
        """Advance to the nearest point within ``search_ahead`` metres ahead; return the index."""
        path = self.path
        s0 = path.s[self.index]
        stop = int(path.index_at(s0 + self.search_ahead)) + 1
        window = path.points[self.index:stop]
        d2 = (window[:, 0] - pose[0]) ** 2 + (window[:, 1] - pose[1]) ** 2
        self.index = self.index + int(np.argmin(d2))
        return self.index

    @property
    def remaining(self) -> float:
        return float(self.path.length - self.path.s[self.index])

    def cross_track(self, pose: np.ndarray) -> tuple[float, float]:
        """(signed lateral error, heading error) of ``pose`` w.r.t. the current path point.

        Positive lateral error: the robot is left of the path.
        """
        i = self.index
        px, py = self.path.points[i]
        yaw = self.path.yaw[i]
        lateral = -math.sin(yaw) * (pose[0] - px) + math.cos(yaw) * (pose[1] - py)
        return float(lateral), float(wrap_angle(pose[2] - yaw))

    def point_ahead(self, distance: float) -> int:
        return int(self.path.index_at(self.path.s[self.index] + distance))

    def goal_reached(self, pose: np.ndarray, tolerance: float) -> bool:
        end = self.path.points[-1]
        close = math.hypot(pose[0] - end[0], pose[1] - end[1]) <= tolerance
        # Also near the end *along* the path: the start of a closed loop is close to its end.
        return close and self.remaining <= 2.0 * tolerance + 0.05
