"""A calibrated skid-steer drive: the default robot of the realistic BARN configuration.

What it models, in the order a command goes through it each tick:

1. the diff-drive controller's limits (speed, 20 m/s^2, 25 rad/s^2 for the Jackal), the
   same ``accelerate`` every robot of the simulator uses;
2. a first-order lag of the wheel speeds behind the controller (motor and driver response);
3. friction: the body's longitudinal acceleration cannot exceed what the wheels transmit
   (mu g = 4.9 m/s^2 at mu 0.5), and its lateral acceleration v * omega saturates
   (skidding wheels give way sideways) near ``max_lateral_acc``;
4. skid-steer slip: the body turns at ``yaw_gain`` times the yaw rate the wheels command,
   a gain drawn per episode from ``yaw_gain_range`` (ground, load and tyre wear change it;
   the navigator is not told), and loses forward speed while the wheels scrub in a turn;
5. the base's command watchdog: a command older than 0.25 s is a stop.

The encoders see the wheels (step 2), not the body: wheel odometry over-reports a turn by
1 / yaw_gain and reports wheel spin as motion; an IMU sees the body.

Calibration (tests/sim/test_sim_dynamics.py): against the pybullet wheeled Jackal of
``wheeled.py`` with its fixed settings, on a 2 m/s step, a brake from 2 m/s, a 1 m/s +
2 rad/s turn and the lateral-acceleration saturation of a 2 m/s + 4 rad/s command.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from ..robots import RobotSpec, accelerate
from .base import DriveModel


def _gain_range(value: Any) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"SkidSteerParams.yaw_gain_range must be (low, high), got {value!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high <= 2):
        raise ValueError(f"SkidSteerParams.yaw_gain_range must satisfy 0 < low <= high <= 2, got {value!r}")
    return (low, high)


@attrs.define(frozen=True)
class SkidSteerParams:
    """Parameters of :class:`SkidSteerDrive` (SI units); the defaults are the Jackal's."""

    friction: float = attrs.field(default=0.5, converter=float, validator=V.finite_positive)
    gravity: float = attrs.field(default=9.81, converter=float, validator=V.finite_positive)
    max_lateral_acc: float = attrs.field(default=3.6, converter=float, validator=V.finite_positive)
    """v * omega saturates here (measured 3.57 m/s^2 on the wheeled model, ~3.8 reported)."""
    lag: float = attrs.field(default=0.04, converter=float, validator=V.finite_positive)
    """Time constant (s) of the wheel speeds behind the controller's output."""
    yaw_lag: float = attrs.field(default=0.4, converter=float, validator=V.finite_positive)
    """Time constant (s) of the body's yaw rate behind the wheels: the scrubbing wheels must
    break their sideways grip before the body turns (the wheeled model needs ~1 s to reach a
    2 rad/s turn from straight driving)."""
    yaw_gain_range: tuple[float, float] = attrs.field(default=(0.6, 1.0), converter=_gain_range)
    turn_speed_loss: float = attrs.field(default=0.07, converter=float, validator=V.number(ge=0, lt=1, finite=True))
    """Fraction of forward speed lost per rad/s of commanded yaw rate (scrubbing wheels)."""
    command_timeout: float = attrs.field(default=0.25, converter=float, validator=V.finite_positive)

    @property
    def max_longitudinal_acc(self) -> float:
        return self.friction * self.gravity


class SkidSteerDrive(DriveModel):
    """The skid-steer model. ``yaw_gain`` fixes the gain instead of drawing it per episode."""

    name = "skid-steer"

    def __init__(self, params: SkidSteerParams | None = None, yaw_gain: float | None = None) -> None:
        self.params = params or SkidSteerParams()
        if yaw_gain is not None and not (math.isfinite(yaw_gain) and 0 < yaw_gain <= 2):
            raise ValueError(f"SkidSteerDrive.yaw_gain must be in (0, 2], got {yaw_gain!r}")
        self._fixed_gain = yaw_gain
        self.command_timeout = self.params.command_timeout
        self.yaw_gain = yaw_gain if yaw_gain is not None else float(np.mean(self.params.yaw_gain_range))
        self._controller = np.zeros(3)
        self._wheels = np.zeros(3)
        self._body = np.zeros(3)

    def bind(self, spec: RobotSpec, rng: np.random.Generator) -> None:
        super().bind(spec, rng)
        if spec.drive.value != "differential":
            raise ValueError(f"SkidSteerDrive models a differential (skid-steer) base; robot {spec.name!r} "
                             f"is {spec.drive.value}")
        self._draw()

    def _draw(self) -> None:
        if self._fixed_gain is None:
            low, high = self.params.yaw_gain_range
            self.yaw_gain = float(self.rng.uniform(low, high))

    def reset(self, pose: np.ndarray) -> None:
        self.halt(pose)

    def halt(self, pose: np.ndarray) -> None:
        self._controller[:] = 0.0
        self._wheels[:] = 0.0
        self._body[:] = 0.0

    def step(self, command: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        target = np.array([command[0], 0.0, command[2]])
        self._controller = accelerate(self.spec, self._controller, target, dt)
        self._wheels += (self._controller - self._wheels) * (1.0 - math.exp(-dt / p.lag))
        wheel_v, wheel_w = self._wheels[0], self._wheels[2]
        v, w = self._body[0], self._body[2]
        # Longitudinal: the body follows the wheels as fast as friction allows.
        v_goal = wheel_v * max(0.0, 1.0 - p.turn_speed_loss * abs(wheel_w))
        dv_max = p.max_longitudinal_acc * dt
        v += float(np.clip(v_goal - v, -dv_max, dv_max))
        # Yaw: a fraction of the commanded turn, within the lateral-acceleration limit.
        w_goal = self.yaw_gain * wheel_w
        if abs(v) > 1e-6:
            w_cap = p.max_lateral_acc / abs(v)
            w_goal = float(np.clip(w_goal, -w_cap, w_cap))
        w += (w_goal - w) * (1.0 - math.exp(-dt / p.yaw_lag))
        self._body = np.array([v, 0.0, w])
        return self._body.copy(), self._wheels.copy()

    def describe(self) -> dict:
        return {"model": self.name, "yaw_gain": round(self.yaw_gain, 4), **attrs.asdict(self.params)}
