"""Odometry: ground truth, or wheel odometry with noise that drifts like the real thing."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.config import validators as V

from ..robots import integrate
from .base import Sensor

if TYPE_CHECKING:
    from ..body import SimRobot


@attrs.define(frozen=True)
class OdometryConfig:
    """``noisy=False`` reports the true pose and twist. ``noisy=True`` integrates the wheel
    twist (which ignores slip) with relative Gaussian errors per reading, so the pose drifts."""

    rate_hz: float = attrs.field(default=50.0, converter=float, validator=V.finite_positive)
    noisy: bool = False
    linear_noise: float = attrs.field(default=0.02, converter=float, validator=V.finite_non_negative)
    angular_noise: float = attrs.field(default=0.03, converter=float, validator=V.finite_non_negative)
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


@attrs.define(frozen=True, eq=False)
class OdometryReading:
    stamp: float
    frame_id: str
    child_frame_id: str
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    omega: float

    @property
    def pose(self) -> np.ndarray:
        return np.array([self.x, self.y, self.yaw])

    @property
    def twist(self) -> np.ndarray:
        return np.array([self.vx, self.vy, self.omega])

    def to_msg(self) -> Any:
        from ..msgs import odometry_to_msg

        return odometry_to_msg(self)


class Odometry(Sensor):
    def __init__(self, robot: SimRobot, config: OdometryConfig | None = None, name: str = "odom") -> None:
        super().__init__(robot, name)
        self.config = config or OdometryConfig()
        self.rate_hz = self.config.rate_hz
        self._estimate = robot.pose.copy()
        self._last_stamp: float | None = None

    def reset(self) -> None:
        self._estimate = self.robot.pose.copy()
        self._last_stamp = None

    def read(self, stamp: float) -> OdometryReading:
        cfg, robot = self.config, self.robot
        if not cfg.noisy:
            pose, twist = robot.pose, robot.twist
        else:
            wheel = robot.wheel_twist
            scale = np.array([cfg.linear_noise, cfg.linear_noise, cfg.angular_noise])
            twist = wheel + np.abs(wheel) * scale * self.rng.standard_normal(3)
            dt = 0.0 if self._last_stamp is None else stamp - self._last_stamp
            self._estimate = integrate(self._estimate, twist, dt)
            pose = self._estimate
        self._last_stamp = stamp
        return OdometryReading(stamp, cfg.frame_id, cfg.child_frame_id, float(pose[0]), float(pose[1]),
                               float(pose[2]), float(twist[0]), float(twist[1]), float(twist[2]))
