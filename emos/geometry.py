"""Planar geometry every layer shares: angle wrapping, yaw <-> quaternion, a message's pose.

One home for these, so the simulator, the navigation stack, the UI and the interop code agree
to the last bit on what a heading is (a planar robot's yaw about z, wrapped to [-pi, pi)).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, overload

import numpy as np

__all__ = ["wrap_angle", "yaw_of_quaternion", "quaternion_of_yaw", "planar_pose", "integrate_pose", "arc_steps", "PoseHistory"]

_TAU = 2.0 * math.pi


@overload
def wrap_angle(angle: float) -> float: ...
@overload
def wrap_angle(angle: np.ndarray) -> np.ndarray: ...


def wrap_angle(angle: Any) -> Any:
    """``angle`` (rad; a number or an array) wrapped to [-pi, pi)."""
    if isinstance(angle, (float, int)):
        return (angle + math.pi) % _TAU - math.pi  # plain arithmetic: 10x numpy's cost on a scalar
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def yaw_of_quaternion(x: float, y: float, z: float, w: float) -> float:
    """The rotation about z (rad) of the unit quaternion (x, y, z, w)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_of_yaw(yaw: float) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation by ``yaw`` (rad) about z."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


_POSE_TYPES = "Odometry, PoseWithCovarianceStamped, PoseStamped, Pose or Pose2D"


def planar_pose(msg: Any) -> tuple[float, float, float]:
    """(x, y, yaw) of an Odometry, PoseWithCovarianceStamped, PoseStamped, Pose or Pose2D message
    (by field names: the ROS types and ours alike). Raises TypeError for anything else."""
    if hasattr(msg, "theta") and hasattr(msg, "x"):  # Pose2D
        return float(msg.x), float(msg.y), float(msg.theta)
    pose = msg
    inner = getattr(pose, "pose", None)
    while inner is not None and not hasattr(pose, "position"):  # Odometry.pose.pose, PoseStamped.pose
        pose, inner = inner, getattr(inner, "pose", None)
    position, orientation = getattr(pose, "position", None), getattr(pose, "orientation", None)
    if position is None or orientation is None:
        raise TypeError(f"expected a pose message ({_POSE_TYPES}), got {type(msg).__name__}")
    q = orientation
    return float(position.x), float(position.y), yaw_of_quaternion(q.x, q.y, q.z, q.w)


def _arc_factors(dth: float, dt: float) -> tuple[float, float]:
    """(integral of cos, integral of sin) of the heading change over the step, per unit speed;
    written through ``dth`` so that a straight step (omega -> 0) is well conditioned."""
    if abs(dth) < 1e-6:
        return (1.0 - dth * dth / 6.0) * dt, dth / 2.0 * dt
    return math.sin(dth) / dth * dt, (1.0 - math.cos(dth)) / dth * dt


def _ndim(value: Any) -> int:
    return value.ndim if isinstance(value, np.ndarray) else int(np.ndim(value))


def integrate_pose(pose: Any, twist: Any, dt: Any) -> np.ndarray:
    """The exact pose (x, y, yaw) after holding the body twist (vx, vy, omega) for ``dt`` s: arcs,
    not Euler steps, so long horizons with coarse steps stay exact. Broadcasts over leading axes
    (poses, twists and steps of a rollout); one pose and one twist take a scalar path, the
    simulator's per-tick case. The heading comes out wrapped to [-pi, pi)."""
    if _ndim(pose) == 1 and _ndim(twist) == 1 and not isinstance(dt, np.ndarray):
        x, y, th = pose
        vx, vy, om = twist
        step = float(dt)
        a, b = _arc_factors(om * step, step)
        dx_b, dy_b = vx * a - vy * b, vx * b + vy * a  # displacement in the start's body frame
        c, s = math.cos(th), math.sin(th)
        return np.array([x + c * dx_b - s * dy_b, y + s * dx_b + c * dy_b, wrap_angle(th + om * step)])
    pose = np.asarray(pose, dtype=np.float64)
    x, y, th = pose[..., 0], pose[..., 1], pose[..., 2]
    dx_b, dy_b, dth = arc_steps(twist, dt)
    c, s = np.cos(th), np.sin(th)
    return np.stack(np.broadcast_arrays(x + c * dx_b - s * dy_b, y + s * dx_b + c * dy_b, wrap_angle(th + dth)), axis=-1)


def arc_steps(twist: Any, dt: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dx, dy, dyaw)`` of holding each body twist (..., 3) for ``dt``: the displacement in the
    body frame at the step's start, and the heading change (the arcs of :func:`integrate_pose`)."""
    cmd = np.asarray(twist, dtype=np.float64)
    vx, vy, om = cmd[..., 0], cmd[..., 1], cmd[..., 2]
    dth = om * dt
    small = np.abs(dth) < 1e-6
    safe = np.where(small, 1.0, dth)
    a = np.where(small, 1.0 - dth**2 / 6.0, np.sin(safe) / safe) * dt
    b = np.where(small, dth / 2.0, (1.0 - np.cos(safe)) / safe) * dt
    return vx * a - vy * b, vx * b + vy * a, dth


class PoseHistory:
    """Where the robot was over the last ``span`` seconds: look up its pose at a measurement's
    stamp, as tf2 looks a transform up at a message's time. A camera detection projected with
    the pose of a later control step lands off by the turn made in between; the vision follower
    tracked the person 3x worse in the runs where its step came a frame after the picture.

    ``add(t, pose)`` in time order (an older or repeated time is ignored); ``at(t)`` interpolates
    (yaw along the shorter way round), and clamps to the oldest or newest pose outside the span."""

    def __init__(self, span: float = 2.0) -> None:
        if not span > 0:
            raise ValueError(f"PoseHistory span must be > 0 s, got {span}")
        self.span = span
        self._poses: deque[tuple[float, np.ndarray]] = deque()

    def add(self, t: float, pose: Any) -> None:
        if self._poses and t <= self._poses[-1][0]:
            return
        self._poses.append((t, np.asarray(pose, dtype=np.float64)[:3].copy()))
        while len(self._poses) > 2 and self._poses[1][0] < t - self.span:
            self._poses.popleft()

    @property
    def span_times(self) -> tuple[float, float] | None:
        """(oldest, newest) time held; None: nothing added yet."""
        return (self._poses[0][0], self._poses[-1][0]) if self._poses else None

    def at(self, t: float) -> np.ndarray | None:
        """The pose at time ``t`` (None: nothing added yet)."""
        if not self._poses:
            return None
        first: np.ndarray = self._poses[0][1]
        if t <= self._poses[0][0]:
            return first.copy()
        for (t0, p0), (t1, p1) in zip(reversed(list(self._poses)[:-1]), reversed(self._poses)):
            if t0 <= t:
                if t >= t1:
                    return np.array(p1)
                f = (t - t0) / (t1 - t0)
                return np.array([p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]),
                                 wrap_angle(p0[2] + f * wrap_angle(float(p1[2] - p0[2])))])
        return np.array(self._poses[-1][1])
