"""What the base really does with a velocity command: a response model for local planners.

A skid-steer base does not turn as commanded: its body reaches a fraction of the commanded
yaw rate (the *yaw gain*: ground, load and tyres change it from run to run), after a lag,
within a lateral-acceleration limit, and its speed changes only as fast as traction allows.
A planner that checks arcs of the *commanded* (v, omega) clips obstacles it thought it would
miss. With a :class:`ResponseConfig`, the arc planner (``arcs.py``) checks and scores the
arcs the base will *achieve* from its measured twist, with the yaw gain estimated online
(:class:`YawGainEstimator`, from the measured yaw rate, e.g. an IMU's) and a collision
margin that grows with speed.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V


def _bounds(value: Any) -> tuple[float, float]:
    low, high = (float(v) for v in value)
    if not (0 < low <= high):
        raise ValueError(f"ResponseConfig.gain_bounds must satisfy 0 < low <= high, got {value!r}")
    return (low, high)


@attrs.define(frozen=True)
class ResponseConfig:
    """Assumed response of the base (the Jackal's defaults) and how to estimate its yaw gain."""

    yaw_lag: float = attrs.field(default=0.4, validator=V.finite_positive)  # s, body yaw rate behind the command
    speed_acc: float = attrs.field(default=4.5, validator=V.finite_positive)  # m/s^2 the speed can change (traction)
    lateral_acc: float = attrs.field(default=3.4, validator=V.finite_positive)  # m/s^2, v * omega saturates here
    prior_gain: float = attrs.field(default=0.8, validator=V.finite_positive)  # yaw gain until estimated
    gain_bounds: tuple[float, float] = attrs.field(default=(0.4, 1.2), converter=_bounds)
    forgetting: float = attrs.field(default=0.97, validator=V.number(gt=0, le=1))  # per control step
    min_excitation: float = attrs.field(default=1.0, validator=V.finite_non_negative)  # (rad/s)^2 of turning seen before trusting
    speed_margin: float = attrs.field(default=0.04, validator=V.finite_non_negative)  # m of extra margin per m/s


class YawGainEstimator:
    """Least squares (with forgetting) of measured yaw rate against the lagged command."""

    def __init__(self, config: ResponseConfig, control_dt: float) -> None:
        if not control_dt > 0:
            raise ValueError(f"YawGainEstimator: control_dt must be > 0, got {control_dt!r}")
        self.cfg, self.dt = config, float(control_dt)
        self.reset()

    def reset(self) -> None:
        self._expected = 0.0  # commanded yaw rate through the lag: what gain 1 would give now
        self._sxy = 0.0
        self._sxx = 0.0
        self.gain = self.cfg.prior_gain

    def update(self, commanded: float, speed: float, measured: float) -> float:
        """After a control step that commanded ``commanded`` rad/s; ``measured`` is the body's
        yaw rate now (gyro), ``speed`` its forward speed. Returns the current estimate."""
        cfg = self.cfg
        alpha = 1.0 - math.exp(-self.dt / cfg.yaw_lag)
        self._expected += (commanded - self._expected) * alpha
        x = self._expected
        # Samples where the lateral-acceleration limit, not the gain, sets the yaw rate would
        # bias the estimate low: skip them.
        if abs(speed * x * self.gain) < 0.8 * cfg.lateral_acc and math.isfinite(measured):
            self._sxy = cfg.forgetting * self._sxy + x * measured
            self._sxx = cfg.forgetting * self._sxx + x * x
        if self._sxx >= cfg.min_excitation:
            low, high = cfg.gain_bounds
            self.gain = float(np.clip(self._sxy / self._sxx, low, high))
        return self.gain


def achieved_arcs(v_cmd: float, turns: np.ndarray, t: np.ndarray, v0: float, w0: float, gain: float,
                  cfg: ResponseConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses (dx, dy, heading) relative to the start, shape (turns, samples), that the base
    achieves at times ``t`` (increasing, > 0) from twist (v0, w0) under commands (v_cmd, turns)."""
    dt = np.diff(np.concatenate([[0.0], t]))
    # Speed: towards the command at the traction limit.
    v = v0 + np.clip(v_cmd - v0, -cfg.speed_acc * t, cfg.speed_acc * t)  # (samples,)
    target = gain * np.asarray(turns, dtype=float)[:, None]  # (turns, 1)
    w = target + (w0 - target) * np.exp(-t / cfg.yaw_lag)[None, :]
    cap = cfg.lateral_acc / np.maximum(np.abs(v), 1e-3)
    w = np.clip(w, -cap, cap)
    heading = np.cumsum(w * dt, axis=1)
    mid = heading - 0.5 * w * dt  # midpoint heading of each step
    dx = np.cumsum(v * dt * np.cos(mid), axis=1)
    dy = np.cumsum(v * dt * np.sin(mid), axis=1)
    return dx, dy, heading
