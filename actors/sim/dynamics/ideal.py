"""The ideal drive: the robot does what it is told, within its speed and acceleration limits.

Today's kinematic model (``emos bench barn --ideal``): optionally a constant fraction of wheel
motion lost to ``slip`` (the body moves less than the encoders report) and a relative
per-tick ``actuation_noise`` on the achieved twist.
"""
from __future__ import annotations

import numpy as np

from ..robots import accelerate
from .base import DriveModel


class IdealDrive(DriveModel):
    name = "ideal"

    def __init__(self, slip: float = 0.0, actuation_noise: float = 0.0) -> None:
        if not 0.0 <= slip < 1.0:
            raise ValueError(f"IdealDrive slip must be in [0, 1), got {slip!r}")
        if not actuation_noise >= 0:
            raise ValueError(f"IdealDrive actuation_noise must be >= 0, got {actuation_noise!r}")
        self.slip, self.actuation_noise = float(slip), float(actuation_noise)
        self._wheels = np.zeros(3)

    def reset(self, pose: np.ndarray) -> None:
        self._wheels = np.zeros(3)

    def halt(self, pose: np.ndarray) -> None:
        self._wheels = np.zeros(3)

    def step(self, command: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        self._wheels = accelerate(self.spec, self._wheels, command, dt)
        actual = self._wheels * (1.0 - self.slip)
        if self.actuation_noise > 0 and np.any(actual):
            actual = actual * (1.0 + self.actuation_noise * self.rng.standard_normal(3))
        return actual, self._wheels.copy()

    def describe(self) -> dict:
        return {"model": self.name, "slip": self.slip, "actuation_noise": self.actuation_noise}
