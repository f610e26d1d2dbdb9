"""Critical (emergency stop) and slowdown zone checks over a scan or a point cloud.

Distances are measured from the robot's footprint edge, not its centre, and only for points
inside a cone of ``critical_zone_angle`` degrees around the direction of travel (behind the
robot when it reverses). Below ``critical_zone_distance`` the robot must stop; between that
and ``slowdown_zone_distance`` its speed is scaled down linearly; beyond, untouched.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from emos.geometry import wrap_angle

from ..controllers.base import in_range, setters
from ..controllers.sensors import LaserScan2D
from ..robot import RobotConfig, RobotGeometry

__all__ = ["SafetyZonesConfig", "ZoneCheck", "SafetyZones"]

_ROUND = (RobotGeometry.Type.CYLINDER, RobotGeometry.Type.SPHERE, RobotGeometry.Type.CAPSULE,
          RobotGeometry.Type.CONE)


@attrs.define
class SafetyZonesConfig:
    """Zone sizes (m beyond the footprint) and the cone angle (degrees, full width)."""

    critical_zone_distance: float = attrs.field(default=0.1, converter=float, validator=in_range(0.0, 1e2), on_setattr=setters)
    critical_zone_angle: float = attrs.field(default=90.0, converter=float, validator=in_range(0.0, 360.0), on_setattr=setters)
    slowdown_zone_distance: float = attrs.field(default=0.3, converter=float, validator=in_range(0.0, 1e2), on_setattr=setters)
    min_height: float = attrs.field(default=-math.inf, converter=float)  # point clouds: z window
    max_height: float = attrs.field(default=math.inf, converter=float)

    def __attrs_post_init__(self) -> None:
        if self.slowdown_zone_distance < self.critical_zone_distance:
            raise ValueError(f"SafetyZonesConfig: slowdown_zone_distance ({self.slowdown_zone_distance}) "
                             f"must be >= critical_zone_distance ({self.critical_zone_distance})")


@attrs.define(frozen=True)
class ZoneCheck:
    """``factor`` scales the command: 0 = emergency stop, 1 = free."""

    factor: float
    min_distance: float  # nearest obstacle beyond the footprint inside the cone (inf: none)

    @property
    def emergency_stop(self) -> bool:
        return self.factor == 0.0


class SafetyZones:
    """Zone checks for one robot; caches per-beam geometry of a fixed scan layout."""

    def __init__(self, robot: RobotConfig, config: SafetyZonesConfig | None = None,
                 sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.robot = robot
        self.config = config or SafetyZonesConfig()
        self.sensor_pose = sensor_pose
        self._scan_key: tuple | None = None
        self._round = robot.geometry_type in _ROUND and sensor_pose[:2] == (0.0, 0.0)

    def _factor(self, d: float) -> ZoneCheck:
        cfg = self.config
        if d <= cfg.critical_zone_distance:
            return ZoneCheck(0.0, d)
        if d < cfg.slowdown_zone_distance:
            return ZoneCheck((d - cfg.critical_zone_distance) / (cfg.slowdown_zone_distance - cfg.critical_zone_distance), d)
        return ZoneCheck(1.0, d)

    def _cone_cos(self) -> float:
        return math.cos(math.radians(0.5 * self.config.critical_zone_angle))

    def check_points(self, points: np.ndarray, direction: float = 0.0) -> ZoneCheck:
        """Points (N, 2|3) in the sensor frame; ``direction`` of travel (rad, robot frame)."""
        pts = np.asarray(points, dtype=np.float32)
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise ValueError(f"points: expected an (N, 2) or (N, 3) array, got shape {pts.shape}")
        x, y = pts[:, 0], pts[:, 1]
        keep = np.isfinite(x) & np.isfinite(y)
        if pts.shape[1] == 3:
            z = pts[:, 2]
            keep &= (z >= self.config.min_height) & (z <= self.config.max_height)
        sx, sy, syaw = self.sensor_pose
        if (sx, sy, syaw) != (0.0, 0.0, 0.0):
            c, s = np.float32(math.cos(syaw)), np.float32(math.sin(syaw))
            x, y = sx + c * x - s * y, sy + s * x + c * y
        # Cone test without arctan: angle to the travel direction within half the cone.
        dx, dy = np.float32(math.cos(direction)), np.float32(math.sin(direction))
        along = x * dx + y * dy
        norm = np.sqrt(x * x + y * y)
        keep &= along >= norm * np.float32(self._cone_cos())
        if not np.any(keep):
            return ZoneCheck(1.0, math.inf)
        if self.robot.geometry_type in _ROUND:
            d = float(norm[keep].min()) - self.robot.radius
        else:
            # Exact footprint distance only where it can be the minimum: a point at centre
            # distance n is at least n - r_out away, the nearest at most n_min - r_in.
            n = norm[keep]
            cand = n <= n.min() + (self.robot.radius - self.robot.inner_radius) + 1e-6
            xs, ys = x[keep][cand], y[keep][cand]
            d = float(self.robot.footprint_distance(np.stack([xs, ys], -1).astype(np.float64)).min())
        return self._factor(d)

    def check_scan(self, scan: LaserScan2D, direction: float = 0.0) -> ZoneCheck:
        """Zone check on a LaserScan (inf/NaN beams are not obstacles)."""
        key = (scan.ranges.size, scan.angle_min, scan.angle_increment, direction,
               None if scan.angles is None else float(scan.angles.sum()))
        if key != self._scan_key:
            ang = scan.beam_angles()
            if self._round:
                # Robot-centred sensor and round footprint: distance beyond = range - radius,
                # and the cone is a fixed set of beams. Cache it; a check is then one gather.
                rel = np.abs(wrap_angle(ang - direction))
                self._cone_idx = np.nonzero(rel <= math.radians(0.5 * self.config.critical_zone_angle))[0]
            self._cos, self._sin = np.cos(ang), np.sin(ang)
            self._scan_key = key
        if self._round:
            r = scan.ranges[self._cone_idx]
            valid = r[(r >= scan.range_min) & (r <= scan.range_max)]  # NaN/inf compare False
            if valid.size == 0:
                return ZoneCheck(1.0, math.inf)
            return self._factor(float(valid.min()) - self.robot.radius)
        mask = scan.valid_mask()
        r = scan.ranges[mask]
        return self.check_points(np.stack([r * self._cos[mask], r * self._sin[mask]], -1), direction)

    def limit(self, command: np.ndarray, obstacles: LaserScan2D | np.ndarray) -> tuple[np.ndarray, ZoneCheck]:
        """Scale the linear part of ``command`` by the zone factor of its direction of travel.

        Pure rotation is never blocked here (it cannot drive into anything ahead); the
        maneuvers module checks the space around the robot before rotating in place.
        """
        cmd = np.asarray(command, dtype=np.float64).copy()
        speed = math.hypot(cmd[0], cmd[1])
        if speed < 1e-9:
            return cmd, ZoneCheck(1.0, math.inf)
        direction = math.atan2(cmd[1], cmd[0])
        if isinstance(obstacles, LaserScan2D):
            check = self.check_scan(obstacles, direction)
        else:
            check = self.check_points(obstacles, direction)
        cmd[:2] *= check.factor
        if check.emergency_stop:
            cmd[2] = 0.0
        return cmd, check
