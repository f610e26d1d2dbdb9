"""Wheel odometry fused with an IMU's yaw: what a real base's state estimator gives a navigator.

Position advances by the *wheel* speed (encoders: they count wheel spin and ignore slip, with
a per-episode scale error and per-tick noise) along a heading integrated from a *gyro* (it
sees the body's real yaw rate, plus a per-episode bias and white noise). This is what the
Jackal's ``odometry/filtered`` (robot_localization over wheel odometry and IMU) provides:
the heading drifts slowly with the gyro bias, the distance with the wheel scale error and
slip, and a skid-steer turn is seen as the body really turns (the wheels alone over-report
it by the slip factor). Never ground truth.

It integrates every physics tick (``on_tick``) and publishes at ``rate_hz``; the readings
are :class:`OdometryReading`, so everything that takes odometry takes it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import attrs
import numpy as np

from emos.config import validators as V

from ..robots import integrate
from .base import Sensor
from .odometry import OdometryReading

if TYPE_CHECKING:
    from ..body import SimRobot
    from ..world import World


@attrs.define(frozen=True)
class WheelImuOdometryConfig:
    rate_hz: float = attrs.field(default=50.0, converter=float, validator=V.finite_positive)
    wheel_scale_std: float = attrs.field(default=0.01, converter=float, validator=V.finite_non_negative)
    """Relative error of the wheel radius, drawn once per episode (tyre wear, load)."""
    wheel_noise: float = attrs.field(default=0.02, converter=float, validator=V.finite_non_negative)
    """Relative standard deviation of the per-tick wheel-speed error."""
    gyro_bias_std: float = attrs.field(default=0.005, converter=float, validator=V.finite_non_negative)
    """rad/s; the bias is drawn once per episode (a MEMS gyro after its start-up calibration)."""
    gyro_noise: float = attrs.field(default=0.02, converter=float, validator=V.finite_non_negative)
    """rad/s, standard deviation of each tick's gyro reading error."""
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


class WheelImuOdometry(Sensor):
    """Odometry from wheel encoders and a gyro (see the module docstring)."""

    def __init__(self, robot: SimRobot, config: WheelImuOdometryConfig | None = None, name: str = "odom") -> None:
        super().__init__(robot, name)
        self.config = config or WheelImuOdometryConfig()
        self.rate_hz = self.config.rate_hz
        self._estimate = robot.pose.copy()
        self._twist = np.zeros(3)
        self.wheel_scale = 1.0
        self.gyro_bias = 0.0

    def bind(self, world: World, rng: np.random.Generator) -> None:
        super().bind(world, rng)
        self._draw()

    def _draw(self) -> None:
        cfg = self.config
        self.wheel_scale = 1.0 + cfg.wheel_scale_std * float(self.rng.standard_normal())
        self.gyro_bias = cfg.gyro_bias_std * float(self.rng.standard_normal())

    def reset(self) -> None:
        """A new episode: estimate at the robot's pose, new scale error and bias."""
        self._estimate = self.robot.pose.copy()
        self._twist = np.zeros(3)
        self._draw()

    def on_tick(self, stamp: float) -> None:
        cfg, robot = self.config, self.robot
        dt = self.bound_world.clock.dt
        wheel_v = float(robot.wheel_twist[0])
        v = wheel_v * self.wheel_scale * (1.0 + cfg.wheel_noise * float(self.rng.standard_normal()))
        omega = float(robot.twist[2]) + self.gyro_bias + cfg.gyro_noise * float(self.rng.standard_normal())
        self._twist = np.array([v, 0.0, omega])
        self._estimate = integrate(self._estimate, self._twist, dt)

    def read(self, stamp: float) -> OdometryReading:
        cfg, (x, y, yaw), (vx, vy, w) = self.config, self._estimate, self._twist
        return OdometryReading(stamp, cfg.frame_id, cfg.child_frame_id, float(x), float(y), float(yaw),
                               float(vx), float(vy), float(w))
