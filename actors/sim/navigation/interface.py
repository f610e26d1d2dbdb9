"""The contract between a simulation harness and whatever drives the robot."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import attrs
import numpy as np

from ..robots import RobotSpec
from ..sensors.lidar import LidarConfig, ScanReading


@attrs.define(frozen=True)
class NavTask:
    """What a navigator is told before a run. No map: it sees the world through its lidar."""

    robot: RobotSpec
    start: tuple[float, float, float]
    goal: tuple[float, float]
    goal_radius: float
    lidar: LidarConfig
    control_rate_hz: float


@attrs.define(frozen=True, eq=False)
class Observation:
    stamp: float
    pose: np.ndarray  # (x, y, yaw) from odometry
    twist: np.ndarray  # (vx, vy, omega) body frame
    scan: ScanReading | None  # the latest sweep (may repeat if the lidar is slower)


@runtime_checkable
class Navigator(Protocol):
    """Drives a robot to a goal: ``reset`` once per run, ``step`` at the control rate.

    ``step`` returns the body-frame velocity command (vx, vy, omega). ``plan`` is the current
    global path (N, 2) or None, used only for pictures.
    """

    name: str
    plan: np.ndarray | None

    def reset(self, task: NavTask) -> None: ...

    def step(self, obs: Observation) -> tuple[float, float, float]: ...
