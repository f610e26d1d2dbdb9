"""What a robot drive model is: commanded twist in, achieved body twist out, every tick.

A :class:`~emos.actors.sim.body.SimRobot` owns one drive model. Each physics tick it hands the
model the commanded body twist (already clipped to the robot's speed limits) and gets back
two twists: what the body really did (ground truth, integrated into the pose) and what the
wheels turned at (what encoders, hence wheel odometry, report). The two differ whenever the
wheels slip: a skid-steer base that turns less than commanded, or spins its wheels while
accelerating harder than friction allows.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from emos.geometry import wrap_angle

if TYPE_CHECKING:
    from ..robots import RobotSpec


class DriveModel:
    """Base class. ``command_timeout`` (seconds, None = none) is the base's own watchdog: a
    command older than that is replaced by a stop, as the Jackal's controller does after 0.25 s."""

    name: str = "drive"
    command_timeout: float | None = None

    def bind(self, spec: RobotSpec, rng: np.random.Generator) -> None:
        """Attach to a robot; ``rng`` is the robot's seeded stream (per-episode draws come from it)."""
        self.spec, self.rng = spec, rng

    def reset(self, pose: np.ndarray) -> None:
        """At rest at ``pose`` (x, y, yaw); a new episode."""

    def step(self, command: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``dt`` s toward ``command`` (vx, vy, omega); return (body twist, wheel twist)."""
        raise NotImplementedError

    def halt(self, pose: np.ndarray) -> None:
        """The body was stopped by a contact and put back at ``pose``: at rest there now."""

    def close(self) -> None:
        """Release what the model holds (a private physics client)."""

    def describe(self) -> dict:
        """The model's parameters for reports (including per-episode draws)."""
        return {"model": self.name}


def twist_between(pose0: np.ndarray, pose1: np.ndarray, dt: float) -> np.ndarray:
    """The constant body twist that carries ``pose0`` to ``pose1`` in ``dt`` s: the exact inverse
    of :func:`emos.actors.sim.robots.integrate` (so re-integrating it reproduces ``pose1``)."""
    x0, y0, yaw0 = (float(v) for v in pose0)
    dyaw = wrap_angle(float(pose1[2]) - yaw0)
    c, s = np.cos(yaw0), np.sin(yaw0)
    dx, dy = float(pose1[0]) - x0, float(pose1[1]) - y0
    bx, by = c * dx + s * dy, -s * dx + c * dy  # displacement in the start's body frame
    if abs(dyaw) < 1e-9:
        return np.array([bx / dt, by / dt, 0.0])
    # integrate(): (bx, by) = [[sin d, cos d - 1], [1 - cos d, sin d]] @ (vx, vy) / w, d = w dt.
    sd, cd = np.sin(dyaw), np.cos(dyaw)
    w = dyaw / dt
    det = sd * sd + (1 - cd) ** 2
    vx = w * (sd * bx + (1 - cd) * by) / det
    vy = w * (-(1 - cd) * bx + sd * by) / det
    return np.array([vx, vy, w])
