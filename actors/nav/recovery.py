"""Recovery behaviors (Nav2's behavior server: spin, back up, drive on heading, wait), as pure
planners over obstacle points in the robot frame.

Each planner checks the robot's footprint over the WHOLE motion before it starts (every pose of
the rotation or the straight drive, through :func:`~emos.actors.nav.controllers.clearance.pose_clearance`,
the one home of footprint clearance) and returns a :class:`BehaviorPlan`: feasible with its
commands, or refused with the reason a person can act on ("back_up refused: obstacle 0.12 m
behind"). The ``Behaviors`` component (components/behaviors.py) re-plans the remaining motion on
every fresh scan while it plays one, so an obstacle that appears mid-way stops it too.

Backing up is where today's unblock maneuvers are blind: a 270 degree scan sees nothing behind
the robot. :func:`plan_back_up` therefore refuses when nothing covers the rear (``rear_seen``
False: no scan beam behind and no local map) instead of driving into the unseen.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from .controllers.clearance import pose_clearance
from .robot import RobotConfig

__all__ = ["BehaviorPlan", "plan_spin", "plan_drive_on_heading", "plan_back_up", "plan_wait", "rear_covered", "scan_covers_rear"]

POSE_STEP = 0.01  # m between checked poses of a straight drive
ANGLE_STEP = math.radians(2.0)  # rad between checked poses of a spin


@attrs.define(frozen=True)
class BehaviorPlan:
    """``commands``: (N, 3) (vx, vy, omega) for N steps of ``dt`` s; empty when refused."""

    name: str
    feasible: bool
    commands: np.ndarray
    dt: float
    reason: str = ""

    @property
    def duration(self) -> float:
        return float(self.commands.shape[0]) * self.dt


def _refuse(name: str, dt: float, reason: str) -> BehaviorPlan:
    return BehaviorPlan(name, False, np.zeros((0, 3)), dt, f"{name} refused: {reason}")


def _check_number(name: str, what: str, value: float, positive: bool = True) -> float:
    v = float(value)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{name}: {what} must be a finite number{' > 0' if positive else ''}, got {value!r}")
    return v


def _points(obstacles: np.ndarray | None) -> np.ndarray:
    pts = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
    return pts[np.all(np.isfinite(pts), axis=1)]


def plan_spin(robot: RobotConfig, obstacles: np.ndarray | None, angle: float, *, max_omega: float = 0.5,
              dt: float = 0.1, margin: float = 0.02) -> BehaviorPlan:
    """Rotate in place by ``angle`` rad (sign = direction). Refused when the footprint at any
    heading of the rotation comes within ``margin`` m of an obstacle (a round robot only when it
    touches already; a long one when a corner would swing into something)."""
    name = "spin"
    angle = _check_number(name, "angle", angle, positive=False)
    w = _check_number(name, "max_omega", max_omega)
    dt = _check_number(name, "dt", dt)
    if abs(angle) < 1e-6:
        return BehaviorPlan(name, True, np.zeros((0, 3)), dt, "nothing to turn")
    steps = max(2, int(math.ceil(abs(angle) / ANGLE_STEP)) + 1)
    yaws = np.linspace(0.0, angle, steps)
    poses = np.c_[np.zeros(steps), np.zeros(steps), yaws]
    clear = pose_clearance(robot, poses, _points(obstacles))
    if np.any(clear < margin):
        i = int(np.argmax(clear < margin))
        return _refuse(name, dt, f"the footprint would come within {max(clear[i], 0.0):.2f} m of an obstacle "
                                 f"after {math.degrees(abs(yaws[i])):.0f} deg of the {math.degrees(abs(angle)):.0f} deg turn "
                                 f"(margin {margin:g} m)")
    n = max(1, int(math.ceil(abs(angle) / (w * dt))))
    omega = angle / (n * dt)
    return BehaviorPlan(name, True, np.tile([0.0, 0.0, omega], (n, 1)), dt)


def _straight(name: str, robot: RobotConfig, obstacles: np.ndarray | None, distance: float, speed: float,
              dt: float, margin: float, direction: float) -> BehaviorPlan:
    distance = _check_number(name, "distance", distance)
    speed = _check_number(name, "speed", abs(float(speed)))
    dt = _check_number(name, "dt", dt)
    steps = max(2, int(math.ceil(distance / POSE_STEP)) + 1)
    s = np.linspace(0.0, distance, steps)
    poses = np.c_[direction * s, np.zeros(steps), np.zeros(steps)]
    clear = pose_clearance(robot, poses, _points(obstacles))
    if np.any(clear < margin):
        i = int(np.argmax(clear < margin))
        free = max(0.0, float(s[i - 1])) if i > 0 else 0.0
        side = "behind" if direction < 0 else "ahead"
        # How far the nearest obstacle on the way is from the footprint, now.
        gap = _gap(robot, poses[0], _points(obstacles), direction)
        return _refuse(name, dt, f"obstacle {gap:.2f} m {side} (the footprint would come within {margin:g} m "
                                 f"after {free:.2f} m of the {distance:.2f} m)")
    n = max(1, int(math.ceil(distance / (speed * dt))))
    v = direction * distance / (n * dt)
    return BehaviorPlan(name, True, np.tile([v, 0.0, 0.0], (n, 1)), dt)


def _gap(robot: RobotConfig, pose: np.ndarray, pts: np.ndarray, direction: float) -> float:
    """Clearance of the footprint to the nearest point on the driving side of the robot."""
    side = pts[(pts[:, 0] * direction) > 0.0] if pts.shape[0] else pts
    if side.shape[0] == 0:
        return math.inf
    return max(0.0, float(pose_clearance(robot, pose[None, :], side)[0]))


def plan_drive_on_heading(robot: RobotConfig, obstacles: np.ndarray | None, distance: float, *, speed: float = 0.2,
                          dt: float = 0.1, margin: float = 0.05) -> BehaviorPlan:
    """Drive straight ahead ``distance`` m at ``speed`` m/s (Nav2's DriveOnHeading), footprint checked."""
    return _straight("drive_on_heading", robot, obstacles, distance, speed, dt, margin, 1.0)


def rear_covered(angle_min: float, angle_max: float, half_width: float = math.radians(30.0)) -> bool:
    """Whether a scan spanning [angle_min, angle_max] (robot frame) sees the rear sector
    (pi - half_width .. pi + half_width)."""
    span = angle_max - angle_min
    if span >= 2 * math.pi - 1e-6:
        return True
    # Every direction of the rear sector must lie inside the scan's interval (on the circle).
    rear = np.linspace(math.pi - half_width, math.pi + half_width, 31)
    return bool(np.all(np.mod(rear - angle_min, 2 * math.pi) <= span + 1e-9))


def scan_covers_rear(scan: Any) -> bool:
    """:func:`rear_covered` for a LaserScan2D (its beams span angle_min + i * angle_increment)."""
    n = int(np.asarray(scan.ranges).size)
    inc = float(scan.angle_increment) if scan.angle_increment else 2 * math.pi / max(n, 1)
    return rear_covered(float(scan.angle_min), float(scan.angle_min) + inc * n)


def plan_back_up(robot: RobotConfig, obstacles: np.ndarray | None, distance: float, *, speed: float = 0.1,
                 dt: float = 0.1, margin: float = 0.05, rear_seen: bool = True) -> BehaviorPlan:
    """Drive straight back ``distance`` m (Nav2's BackUp). Refused when an obstacle behind would
    come within ``margin`` m of the footprint, or when nothing sees behind the robot."""
    if not rear_seen:
        dt = _check_number("back_up", "dt", dt)
        return _refuse("back_up", dt, "nothing sees behind the robot (the scan does not cover the rear and "
                                      "there is no local map): it will not back up blind")
    return _straight("back_up", robot, obstacles, distance, speed, dt, margin, -1.0)


def plan_wait(duration: float, *, dt: float = 0.1) -> BehaviorPlan:
    """Stand still ``duration`` s (zero commands)."""
    duration = _check_number("wait", "duration", duration)
    dt = _check_number("wait", "dt", dt)
    return BehaviorPlan("wait", True, np.zeros((max(1, int(math.ceil(duration / dt))), 3)), dt)
