"""Velocity commands to the simulated base, with a real base's watchdog.

Accepts ``Twist``, ``TwistStamped`` and Kompass' ``TwistArray`` (a sequence of commands, one per
``array_step`` seconds, that a drive executes in order). A command older than ``timeout``
simulated seconds, or a TwistArray run to its end, stops the robot: a controller that dies or
hangs must not leave the robot driving.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from emos.msgs import Twist, TwistArray, TwistStamped


def twist_values(msg: Any) -> np.ndarray | np.ndarray:
    """(vx, vy, omega) of a Twist / TwistStamped, or (N, 3) of a TwistArray."""
    if isinstance(msg, TwistStamped):
        msg = msg.twist
    if isinstance(msg, Twist):
        return np.array([msg.linear.x, msg.linear.y, msg.angular.z], dtype=float)
    if isinstance(msg, TwistArray):
        lin, ang = np.asarray(msg.linear_velocities, float), np.asarray(msg.angular_velocities, float)
        if lin.shape[0] != ang.shape[0]:
            raise ValueError(f"TwistArray has {lin.shape[0]} linear but {ang.shape[0]} angular velocities")
        return np.c_[lin[:, 0], lin[:, 1], ang[:, 2]] if len(lin) else np.zeros((0, 3))
    raise TypeError(f"Simulator command must be Twist, TwistStamped or TwistArray, got {type(msg).__name__}")


class CommandFollower:
    """Holds the latest command and says what the base should do at a given simulated time."""

    def __init__(self, timeout: float, array_step: float) -> None:
        self.timeout, self.array_step = float(timeout), float(array_step)
        self._commands = np.zeros((0, 3))
        self._since = -math.inf
        self.received = 0
        self.rejected = 0

    def receive(self, msg: Any, now: float) -> None:
        values = twist_values(msg)
        values = values.reshape(-1, 3)
        if not np.all(np.isfinite(values)):
            self.rejected += 1
            raise ValueError(f"Simulator command has non-finite values {values.tolist()!r}; the robot stops")
        self._commands, self._since = values, now
        self.received += 1

    def stop(self) -> None:
        self._commands = np.zeros((0, 3))

    def target(self, now: float) -> np.ndarray:
        """The (vx, vy, omega) to drive at ``now``: zero when stale, absent or used up."""
        if len(self._commands) == 0:
            return np.zeros(3)
        age = now - self._since
        if len(self._commands) == 1:
            return self._commands[0] if age <= self.timeout + 1e-9 else np.zeros(3)
        index = int(math.floor(age / self.array_step + 1e-9))
        return self._commands[index] if 0 <= index < len(self._commands) else np.zeros(3)


def joint_targets(msg: Any) -> tuple[list[str], np.ndarray]:
    """(joint names, positions) of a JointState, or of a JointTrajectory's last point (its goal)."""
    from emos.msgs import JointState, JointTrajectory

    if isinstance(msg, JointState):
        names, positions = list(msg.name), np.asarray(msg.position, dtype=float)
    elif isinstance(msg, JointTrajectory):
        if not msg.points:
            raise ValueError("JointTrajectory has no points")
        names, positions = list(msg.joint_names), np.asarray(msg.points[-1].positions, dtype=float)
    else:
        raise TypeError(f"joint_command must be JointState or JointTrajectory, got {type(msg).__name__}")
    if len(names) != len(positions):
        raise ValueError(f"joint command names {names} and positions {positions.tolist()} differ in length")
    return names, positions
