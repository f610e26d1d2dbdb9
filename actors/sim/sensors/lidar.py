"""2D lidar by pybullet ray batches."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.config import validators as V

from .base import Sensor

if TYPE_CHECKING:
    from ..body import SimRobot


@attrs.define(frozen=True)
class LidarConfig:
    """Defaults model BARN's Hokuyo UST-10LX: 270 deg, 0.25 deg steps, 10 m range."""

    fov_deg: float = attrs.field(default=270.0, converter=float, validator=V.number(gt=0, le=360))
    beams: int = attrs.field(default=1081, converter=int, validator=V.int_at_least(2))
    range_min: float = attrs.field(default=0.06, converter=float, validator=V.finite_positive)
    range_max: float = attrs.field(default=10.0, converter=float, validator=V.finite_positive)
    noise_std: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    rate_hz: float = attrs.field(default=20.0, converter=float, validator=V.finite_positive)
    # Mount on the robot: x, y (m) in the base frame, z (m; None = the robot's lidar height), yaw.
    mount_xy: tuple[float, float] = attrs.field(default=(0.0, 0.0), converter=lambda v: (float(v[0]), float(v[1])))
    mount_z: float | None = None
    mount_yaw: float = attrs.field(default=0.0, converter=float)
    frame_id: str = "laser"

    def __attrs_post_init__(self) -> None:
        if self.range_min >= self.range_max:
            raise ValueError(f"LidarConfig.range_min ({self.range_min}) must be < range_max ({self.range_max})")

    @property
    def angle_min(self) -> float:
        return -math.radians(self.fov_deg) / 2

    @property
    def angle_increment(self) -> float:
        # A full circle must not sample the same direction twice.
        span = math.radians(self.fov_deg)
        return span / self.beams if self.fov_deg == 360 else span / (self.beams - 1)

    @property
    def angle_max(self) -> float:
        return self.angle_min + self.angle_increment * (self.beams - 1)

    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.beams)


@attrs.define(frozen=True, eq=False)
class ScanReading:
    """One sweep, LaserScan-shaped. ``ranges`` are float32 metres; no return is +inf."""

    stamp: float
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    scan_time: float
    ranges: np.ndarray
    sensor_pose: tuple[float, float, float]  # (x, y, yaw) of the lidar in the world when taken

    def points(self) -> np.ndarray:
        """Hit points (N, 2) in the sensor frame."""
        a = self.angle_min + self.angle_increment * np.arange(len(self.ranges))
        ok = np.isfinite(self.ranges)
        r = self.ranges[ok].astype(float)
        return np.c_[r * np.cos(a[ok]), r * np.sin(a[ok])]

    def world_points(self) -> np.ndarray:
        """Hit points (N, 2) in the world frame."""
        x, y, yaw = self.sensor_pose
        p = self.points()
        c, s = math.cos(yaw), math.sin(yaw)
        return np.c_[x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1]]

    def to_msg(self) -> Any:
        from ..msgs import scan_to_msg

        return scan_to_msg(self)


class Lidar(Sensor):
    def __init__(self, robot: SimRobot, config: LidarConfig | None = None, name: str = "lidar") -> None:
        super().__init__(robot, name)
        self.config = config or LidarConfig()
        self.rate_hz = self.config.rate_hz
        self._local_angles = self.config.angles() + self.config.mount_yaw
        self._z = self.config.mount_z if self.config.mount_z is not None else robot.spec.lidar_height

    def sensor_pose(self) -> tuple[float, float, float]:
        x, y, yaw = self.robot.pose
        mx, my = self.config.mount_xy
        c, s = math.cos(yaw), math.sin(yaw)
        return x + c * mx - s * my, y + s * mx + c * my, yaw + self.config.mount_yaw

    def _reach(self, sx: float, sy: float, d: np.ndarray) -> np.ndarray:
        """Each ray's length: the range, or less where it leaves everything it could hit."""
        cfg = self.config
        world = self.bound_world
        bounds = world.ray_bounds() if hasattr(world, "ray_bounds") else None
        full = np.full(len(d), cfg.range_max)
        if bounds is None:
            return full
        xmin, ymin, xmax, ymax = bounds
        if not (xmin <= sx <= xmax and ymin <= sy <= ymax):
            return full  # a sensor outside the box (fixed in the world): no shortcut
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(d[:, 0] > 0, (xmax - sx) / d[:, 0], np.where(d[:, 0] < 0, (xmin - sx) / d[:, 0], np.inf))
            ty = np.where(d[:, 1] > 0, (ymax - sy) / d[:, 1], np.where(d[:, 1] < 0, (ymin - sy) / d[:, 1], np.inf))
        # A little beyond the box so a surface on its edge is still hit.
        return np.clip(np.minimum(tx, ty) + 0.05, cfg.range_min + 1e-3, cfg.range_max)

    def _past_own_body(self, client: Any, sx: float, sy: float, d: np.ndarray, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(hit ids, ranges) of rays that hit the robot's own body, cast again from where they
        have left it. A lidar mounted at the height of its body's top face (a ``RobotConfig``'s
        body: the scan plane is its top) started half its rays inside the body, which Bullet
        reports as hits at the ray's start: ranges of ``range_min``, dropped as invalid. A lidar
        sees the world, not its own mount."""
        (x0, y0, _), (x1, y1, _) = client.getAABB(self.robot.body_id)
        past = float(max(np.hypot(cx - sx, cy - sy) for cx in (x0, x1) for cy in (y0, y1))) + 0.01
        past = np.minimum(max(past, self.config.range_min), reach)
        start = np.empty((len(d), 3))
        end = np.empty((len(d), 3))
        start[:, :2] = (sx, sy) + d * past[:, None]
        end[:, :2] = (sx, sy) + d * reach[:, None]
        start[:, 2] = end[:, 2] = self._z
        ids, _, fractions, _, _ = zip(*client.rayTestBatch(start, end, numThreads=1))
        ids_a = np.array(ids)
        ids_a[ids_a == self.robot.body_id] = -1
        return ids_a, past + np.array(fractions) * (reach - past)

    def read(self, stamp: float) -> ScanReading:
        cfg = self.config
        sx, sy, _ = self.sensor_pose()
        angles = self._local_angles + self.robot.pose[2]
        d = np.c_[np.cos(angles), np.sin(angles)]
        n = len(angles)
        reach = self._reach(sx, sy, d)
        start = np.empty((n, 3))
        end = np.empty((n, 3))
        start[:, :2] = (sx, sy) + d * cfg.range_min
        end[:, :2] = (sx, sy) + d * reach[:, None]
        start[:, 2] = end[:, 2] = self._z
        client = self.bound_world.client
        # numpy arrays go straight in (no tolist); zip(*) splits the result columns in C.
        results = client.rayTestBatch(start, end, numThreads=1)
        ids, _, fractions, _, _ = zip(*results)
        ids_a = np.array(ids)
        frac = np.array(fractions)
        ranges = cfg.range_min + frac * (reach - cfg.range_min)
        own = ids_a == self.robot.body_id
        if own.any():
            ids_a[own], ranges[own] = self._past_own_body(client, sx, sy, d[own], reach[own])
        hit = ids_a >= 0
        if cfg.noise_std > 0:
            ranges = ranges + self.rng.normal(0.0, cfg.noise_std, n)
            ranges = np.maximum(ranges, cfg.range_min)
        ranges = np.where(hit & (ranges <= cfg.range_max), ranges, np.inf).astype(np.float32)
        return ScanReading(
            stamp=stamp, frame_id=cfg.frame_id, angle_min=cfg.angle_min, angle_max=cfg.angle_max,
            angle_increment=cfg.angle_increment, range_min=cfg.range_min, range_max=cfg.range_max,
            scan_time=1.0 / cfg.rate_hz, ranges=ranges,
            sensor_pose=(sx, sy, float(self.robot.pose[2] + cfg.mount_yaw)),
        )
