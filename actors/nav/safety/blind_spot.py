"""What the robot saw around itself recently, for the directions its laser cannot see now.

A Jackal's laser covers 270 degrees: a robot backing out of a dead end is blind behind it. But
it drove in forwards, so the walls behind it were in view a moment ago. :class:`BlindSpotMemory`
keeps the obstacle points of recent scans in the odometry frame (one per grid cell, the newest),
and gives back, in the robot's current frame, the remembered points that lie where the current
scan has no beams: the blind sector. Where the laser does look, its current reading is the
truth (an obstacle that moved away must not block), so memory is never used there.

The memory is local and short: points older than ``memory_time`` or farther than ``radius`` from
the robot are forgotten, so odometry drift over the remembered span stays small, and a
remembered point is only as old as the robot's last look in that direction.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config.validators import in_range

from ..controllers.sensors import LaserScan2D

__all__ = ["BlindSpotConfig", "BlindSpotMemory"]


@attrs.define(kw_only=True, frozen=True)
class BlindSpotConfig:
    """``memory_time`` (s) and ``radius`` (m): how long and how far around the robot obstacle
    points are remembered; ``resolution`` (m): one point is kept per cell of this size."""

    memory_time: float = attrs.field(default=10.0, validator=in_range(min_value=0.1, max_value=600.0))
    radius: float = attrs.field(default=2.0, validator=in_range(min_value=0.1, max_value=50.0))
    resolution: float = attrs.field(default=0.05, validator=in_range(min_value=0.005, max_value=1.0))


def _frame(pose: np.ndarray) -> tuple[float, float, float, float]:
    x, y, yaw = (float(v) for v in pose[:3])
    return x, y, math.cos(yaw), math.sin(yaw)


class BlindSpotMemory:
    def __init__(self, config: BlindSpotConfig | None = None) -> None:
        self.config = config or BlindSpotConfig()
        self._xy = np.zeros((0, 2))  # odometry frame
        self._stamp = np.zeros(0)

    def __len__(self) -> int:
        return len(self._stamp)

    def clear(self) -> None:
        self._xy, self._stamp = np.zeros((0, 2)), np.zeros(0)

    def update(self, pose: np.ndarray, scan: LaserScan2D, now: float, sensor_pose=(0.0, 0.0, 0.0)) -> None:
        """Remember the scan's hit points, taken at robot ``pose`` (x, y, yaw in the odometry frame)."""
        cfg = self.config
        sx, sy, syaw = sensor_pose
        pts = scan.points()
        if len(pts):
            c, s = math.cos(syaw), math.sin(syaw)
            pts = np.c_[sx + c * pts[:, 0] - s * pts[:, 1], sy + s * pts[:, 0] + c * pts[:, 1]]
            pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= cfg.radius]
        x, y, c, s = _frame(pose)
        world = np.c_[x + c * pts[:, 0] - s * pts[:, 1], y + s * pts[:, 0] + c * pts[:, 1]] if len(pts) else np.zeros((0, 2))
        xy = np.vstack([world, self._xy])  # newest first: np.unique keeps the first of each cell
        stamp = np.concatenate([np.full(len(world), now), self._stamp])
        keep = (now - stamp <= cfg.memory_time) & (np.hypot(xy[:, 0] - x, xy[:, 1] - y) <= cfg.radius)
        xy, stamp = xy[keep], stamp[keep]
        if len(xy):
            _, first = np.unique(np.floor(xy / cfg.resolution).astype(np.int64), axis=0, return_index=True)
            xy, stamp = xy[first], stamp[first]
        self._xy, self._stamp = xy, stamp

    def blind_points(self, pose: np.ndarray, scan: LaserScan2D, sensor_pose=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Remembered points (M, 2) in the robot frame at ``pose`` that lie outside the field of
        view of ``scan`` (taken from ``sensor_pose`` on the robot)."""
        if not len(self._xy):
            return np.zeros((0, 2))
        x, y, c, s = _frame(pose)
        dx, dy = self._xy[:, 0] - x, self._xy[:, 1] - y
        local = np.c_[c * dx + s * dy, -s * dx + c * dy]
        sx, sy, syaw = sensor_pose
        bearing = np.arctan2(local[:, 1] - sy, local[:, 0] - sx) - syaw
        angles = scan.beam_angles()
        if angles.size < 2:
            return local
        # The scan's beams cover [lo, hi] (relative to its first beam, so any angle_min works).
        lo = float(angles[0])
        span = float(angles[-1] - lo)
        if abs(span) >= 2 * math.pi - 2 * abs(float(angles[1] - angles[0])):
            return np.zeros((0, 2))  # a full turn: nothing is blind
        rel = np.mod(bearing - lo, 2 * math.pi) if span > 0 else np.mod(lo - bearing, 2 * math.pi)
        return local[rel > abs(span)]
