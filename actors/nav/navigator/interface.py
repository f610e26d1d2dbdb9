"""The contract between a harness (a benchmark, a simulator loop) and a navigator that drives the robot."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import attrs
import numpy as np

from ..robot import RobotConfig


@runtime_checkable
class Scan(Protocol):
    """A planar scan as the navigators read it (LaserScan2D, or a simulator's reading)."""

    angle_min: float
    angle_increment: float
    ranges: np.ndarray

    def points(self) -> np.ndarray: ...


@attrs.define(frozen=True)
class NavTask:
    """What a navigator is told before a run. No map: it sees the world through its lidar."""

    robot: RobotConfig
    start: tuple[float, float, float]
    goal: tuple[float, float]
    goal_radius: float
    scan_mount: tuple[float, float, float]  # (x, y, yaw) of the scanner in the base frame
    control_rate_hz: float
    center_offset: float = 0.0  # footprint centre ahead of the base frame (m)


@attrs.define(frozen=True, eq=False)
class Observation:
    stamp: float
    pose: np.ndarray  # (x, y, yaw) from odometry
    twist: np.ndarray  # (vx, vy, omega) body frame
    scan: Scan | None  # the latest sweep (may repeat if the lidar is slower)


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
