"""Obstacle inputs for controllers and safety: LaserScan, point cloud or occupancy grid.

Each is reduced to one thing, an (M, 2) array of obstacle points in the robot frame, so the
algorithms never care which sensor produced them. Later the message layer fills these types.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.config import validators as V
from emos.geometry import yaw_of_quaternion

__all__ = ["LaserScan2D", "OccupancyGrid2D", "ObstacleInput", "obstacle_points", "sensor_offset"]


def _as_float_array(instance, attribute, value) -> None:
    if value.ndim != 1:
        raise ValueError(f"LaserScan2D.{attribute.name}: expected a 1D array, got shape {value.shape}")


@attrs.define(eq=False)
class LaserScan2D:
    """A planar scan in the sensor frame, with ROS LaserScan semantics.

    ``inf`` means no return within ``range_max`` (free ray), NaN means an invalid reading and
    is ignored; both never become obstacles. ``angles`` may be given explicitly, otherwise
    ``angle_min + i * angle_increment`` (default: N beams over a full turn).
    """

    ranges: np.ndarray = attrs.field(converter=lambda r: np.asarray(r, dtype=np.float64), validator=_as_float_array)
    angle_min: float = attrs.field(default=-math.pi, converter=float)
    angle_increment: float | None = attrs.field(default=None)
    range_min: float = attrs.field(default=0.0, converter=float)
    range_max: float = attrs.field(default=math.inf, converter=float)
    angles: np.ndarray | None = attrs.field(default=None)

    def __attrs_post_init__(self) -> None:
        n = self.ranges.size
        if self.angles is not None:
            self.angles = np.asarray(self.angles, dtype=np.float64).reshape(-1)
            if self.angles.size != n:
                raise ValueError(f"LaserScan2D.angles: expected {n} angles (one per range), "
                                 f"got {self.angles.size}")
        elif self.angle_increment is None:
            self.angle_increment = 2.0 * math.pi / max(n, 1)
        if self.range_min < 0 or not self.range_max > self.range_min:
            raise ValueError(f"LaserScan2D: expected 0 <= range_min < range_max, got "
                             f"{self.range_min}, {self.range_max}")

    def beam_angles(self) -> np.ndarray:
        if self.angles is not None:
            return self.angles
        assert self.angle_increment is not None  # set in __attrs_post_init__
        return self.angle_min + np.arange(self.ranges.size) * float(self.angle_increment)

    def valid_mask(self) -> np.ndarray:
        """Beams that hit something: finite and within [range_min, range_max]."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)

    def points(self) -> np.ndarray:
        """Hit points (M, 2) in the sensor frame."""
        mask = self.valid_mask()
        r = self.ranges[mask]
        a = self.beam_angles()[mask]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


@attrs.define(eq=False)
class OccupancyGrid2D:
    """Occupancy grid with ROS semantics: -1 unknown, 0 free .. 100 occupied.

    ``data`` is indexed ``[row, col]`` = ``[y, x]``; ``origin`` is the (x, y) of the lower-left
    corner of cell (0, 0) in the frame the grid lives in (the robot frame for a local map).
    """

    data: np.ndarray = attrs.field(converter=np.asarray)
    resolution: float = attrs.field(converter=float, validator=V.number(gt=0, finite=True, what="a finite cell size in m"))
    origin: tuple[float, float] = attrs.field(default=(0.0, 0.0), converter=lambda o: (float(o[0]), float(o[1])))
    occupied_threshold: int = attrs.field(default=50)

    @data.validator
    def _check_data(self, attribute, value) -> None:
        if value.ndim != 2:
            raise ValueError(f"OccupancyGrid2D.data: expected a 2D array, got shape {value.shape}")

    def occupied_points(self) -> np.ndarray:
        """Centres (M, 2) of occupied cells."""
        rows, cols = np.nonzero(self.data >= self.occupied_threshold)
        x = self.origin[0] + (cols + 0.5) * self.resolution
        y = self.origin[1] + (rows + 0.5) * self.resolution
        return np.stack([x, y], axis=-1).astype(np.float64)


ObstacleInput = LaserScan2D | OccupancyGrid2D | np.ndarray | None


def sensor_offset(position: np.ndarray | list[float], rotation_quat: np.ndarray | list[float]) -> tuple[float, float, float]:
    """Planar (x, y, yaw) of a sensor mounted at ``position`` with quaternion (x, y, z, w)."""
    qx, qy, qz, qw = (float(v) for v in rotation_quat)
    yaw = yaw_of_quaternion(qx, qy, qz, qw)
    return float(position[0]), float(position[1]), yaw


def obstacle_points(
    obstacles: ObstacleInput,
    sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    z_range: tuple[float, float] = (-math.inf, math.inf),
) -> np.ndarray:
    """Reduce any obstacle input to (M, 2) points in the robot frame.

    ``sensor_pose`` is the sensor's planar pose on the robot; point clouds (N, 3) keep only
    points whose z lies in ``z_range`` (e.g. between the floor and the robot's height).
    NaN/inf points of a cloud are dropped.
    """
    if obstacles is None:
        return np.zeros((0, 2))
    if isinstance(obstacles, LaserScan2D):
        pts = obstacles.points()
    elif isinstance(obstacles, OccupancyGrid2D):
        pts = obstacles.occupied_points()
    else:
        arr = np.asarray(obstacles, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] not in (2, 3):
            raise ValueError(f"obstacles: expected a LaserScan2D, an OccupancyGrid2D or an "
                             f"(N, 2)/(N, 3) point array, got shape {arr.shape}")
        keep = np.all(np.isfinite(arr), axis=1)
        if arr.shape[1] == 3:
            keep &= (arr[:, 2] >= z_range[0]) & (arr[:, 2] <= z_range[1])
        pts = arr[keep, :2]
    sx, sy, syaw = sensor_pose
    if sx == 0.0 and sy == 0.0 and syaw == 0.0:
        return np.ascontiguousarray(pts, dtype=np.float64)
    c, s = math.cos(syaw), math.sin(syaw)
    return np.stack([sx + c * pts[:, 0] - s * pts[:, 1], sy + s * pts[:, 0] + c * pts[:, 1]], axis=-1)
