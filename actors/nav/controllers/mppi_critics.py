"""The critics of the MPPI controller: each scores every sampled trajectory (lower is better).

The set and the parameter names are Nav2's (nav2_mppi_controller), so that a Nav2 user's YAML
translates field by field: ``ConstraintCritic``, ``GoalCritic``, ``GoalAngleCritic``,
``PathAlignCritic``, ``PathFollowCritic``, ``PathAngleCritic``, ``PreferForwardCritic`` and
``ObstaclesCritic``, each with ``enabled``, ``cost_weight`` and ``cost_power``. A critic gives
``cost_weight * term ** cost_power`` per trajectory; the terms are our own formulations of what
Nav2's documentation says each critic does. Obstacles come from this step's obstacle points
through a :class:`~.distance_field.DistanceField` instead of an inflated costmap.
"""
from __future__ import annotations

from typing import Any

import attrs
import numpy as np

from ..kinematics import wrap_angle
from .base import field

__all__ = [
    "Rollouts", "ConstraintCritic", "GoalCritic", "GoalAngleCritic", "PathAlignCritic", "PathFollowCritic",
    "PathAngleCritic", "PreferForwardCritic", "ObstaclesCritic", "CRITICS",
]


@attrs.define
class Rollouts:
    """What the critics see of one optimisation step. Shapes: K trajectories of T steps."""

    vx: np.ndarray  # (K, T) commanded forward speed
    vy: np.ndarray  # (K, T)
    wz: np.ndarray  # (K, T)
    x: np.ndarray  # (K, T) poses after each step
    y: np.ndarray
    yaw: np.ndarray
    dt: float
    pose: np.ndarray  # (3,) the robot now
    path: np.ndarray  # (P, 3) the pruned reference path ahead of the robot (x, y, yaw)
    goal: np.ndarray  # (3,) the path's last pose
    goal_distance: float  # robot to goal, straight line
    distance: Any  # DistanceField or None (no obstacles)
    robot: Any  # RobotConfig
    limits: tuple[float, float, float, float]  # vx_min, vx_max, vy_max, wz_max
    furthest: int = 0  # index in ``path`` of the furthest point any trajectory reaches (set once per step)
    path_distance: Any = None  # DistanceField of path[:furthest + 1] (set once per step)
    path_blocked: bool = False  # more than the allowed share of the path ahead is near an obstacle


def _critic(weight: float, power: int = 1, **extra: Any) -> Any:
    """An attrs class body for a critic: ``enabled``, ``cost_weight``, ``cost_power`` and ``extra``."""
    fields = {"enabled": attrs.field(default=True, converter=bool),
              "cost_weight": field(weight, 0.0, 1e6), "cost_power": field(power, 1, 4, int)}
    fields.update(extra)
    return fields


def _score(critic: Any, term: np.ndarray) -> np.ndarray:
    return critic.cost_weight * (term ** critic.cost_power if critic.cost_power != 1 else term)


ConstraintCritic = attrs.make_class("ConstraintCritic", _critic(4.0))
GoalCritic = attrs.make_class("GoalCritic", _critic(5.0, threshold_to_consider=field(1.4, 0.0, 1e3)))
GoalAngleCritic = attrs.make_class("GoalAngleCritic", _critic(3.0, threshold_to_consider=field(0.5, 0.0, 1e3)))
PathAlignCritic = attrs.make_class("PathAlignCritic", _critic(
    14.0, threshold_to_consider=field(0.5, 0.0, 1e3), offset_from_furthest=field(20, 0, 10_000, int),
    trajectory_point_step=field(3, 1, 100, int), max_path_occupancy_ratio=field(0.05, 0.0, 1.0)))
PathFollowCritic = attrs.make_class("PathFollowCritic", _critic(
    5.0, threshold_to_consider=field(1.4, 0.0, 1e3), offset_from_furthest=field(5, 0, 10_000, int)))
PathAngleCritic = attrs.make_class("PathAngleCritic", _critic(
    2.0, threshold_to_consider=field(0.5, 0.0, 1e3), offset_from_furthest=field(4, 0, 10_000, int),
    max_angle_to_furthest=field(1.0, 0.0, np.pi), forward_preference=attrs.field(default=True, converter=bool)))
PreferForwardCritic = attrs.make_class("PreferForwardCritic", _critic(5.0, threshold_to_consider=field(0.5, 0.0, 1e3)))
ObstaclesCritic = attrs.make_class("ObstaclesCritic", {
    "enabled": attrs.field(default=True, converter=bool), "cost_power": field(1, 1, 4, int),
    "critical_weight": field(20.0, 0.0, 1e6), "repulsion_weight": field(1.5, 0.0, 1e6),
    "collision_cost": field(10000.0, 0.0, 1e9), "collision_margin_distance": field(0.10, 0.0, 10.0),
    "near_goal_distance": field(0.5, 0.0, 1e3), "inflation_radius": field(0.55, 0.0, 10.0),
})


def constraint(c: Any, r: Rollouts) -> np.ndarray:
    """Speed beyond the limits, integrated over the horizon (sampling clips, so this is the
    Ackermann turning-radius constraint in practice: |wz| beyond |vx| * max curvature)."""
    vx_min, vx_max, _vy_max, wz_max = r.limits
    ackermann = r.robot.model_type.name == "ACKERMANN"
    if not ackermann and float(r.vx.min()) >= vx_min and float(r.vx.max()) <= vx_max and float(np.abs(r.wz).max()) <= wz_max:
        return np.zeros(r.vx.shape[0])  # nothing beyond a limit (the usual case: sampling clips)
    over = np.maximum(r.vx - vx_max, 0.0) + np.maximum(vx_min - r.vx, 0.0) + np.maximum(np.abs(r.wz) - wz_max, 0.0)
    if ackermann:
        over = over + np.maximum(np.abs(r.wz) - np.abs(r.vx) * r.robot.max_curvature, 0.0)
    return _score(c, over.sum(axis=1) * r.dt)


def goal(c: Any, r: Rollouts) -> np.ndarray:
    """Near the goal (within ``threshold_to_consider``): the mean distance of the trajectory to it."""
    if r.goal_distance > c.threshold_to_consider:
        return np.zeros(r.x.shape[0])
    d = np.hypot(r.x - r.goal[0], r.y - r.goal[1])
    return _score(c, d.mean(axis=1))


def goal_angle(c: Any, r: Rollouts) -> np.ndarray:
    """Near the goal: the mean heading error to the goal's heading."""
    if r.goal_distance > c.threshold_to_consider:
        return np.zeros(r.x.shape[0])
    return _score(c, np.abs(wrap_angle(r.yaw - r.goal[2])).mean(axis=1))


def _nearest_path_index(r: Rollouts, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # In the trajectories' dtype (float32 for the batch: half the work of float64's).
    px, py = r.path[:, 0].astype(x.dtype), r.path[:, 1].astype(x.dtype)
    d2 = (x[..., None] - px) ** 2 + (y[..., None] - py) ** 2
    return np.asarray(np.argmin(d2, axis=-1))


def path_align(c: Any, r: Rollouts) -> np.ndarray:
    """Away from the goal and while the path ahead is free: the mean distance of the trajectory's
    points (every ``trajectory_point_step``-th) to the path, so the robot keeps to the path when
    nothing stops it, and may leave it when something does."""
    if r.goal_distance < c.threshold_to_consider or r.path_blocked or r.furthest < c.offset_from_furthest or r.path_distance is None:
        return np.zeros(r.x.shape[0])
    step = c.trajectory_point_step
    d = r.path_distance(np.stack([r.x[:, ::step], r.y[:, ::step]], axis=-1))
    return _score(c, d.mean(axis=1, dtype=np.float64))


def path_follow(c: Any, r: Rollouts) -> np.ndarray:
    """Away from the goal: the distance from the trajectory's end to the path point
    ``offset_from_furthest`` beyond the furthest any trajectory reached (progress along the path)."""
    if r.goal_distance < c.threshold_to_consider:
        return np.zeros(r.x.shape[0])
    target = r.path[min(r.furthest + c.offset_from_furthest, r.path.shape[0] - 1)]
    return _score(c, np.hypot(r.x[:, -1] - target[0], r.y[:, -1] - target[1]))


def path_angle(c: Any, r: Rollouts) -> np.ndarray:
    """When the robot faces away from where the path goes (more than ``max_angle_to_furthest``):
    the mean heading error of the trajectory to the direction of that path point."""
    if r.goal_distance < c.threshold_to_consider:
        return np.zeros(r.x.shape[0])
    target = r.path[min(r.furthest + c.offset_from_furthest, r.path.shape[0] - 1)]
    bearing = np.arctan2(target[1] - r.pose[1], target[0] - r.pose[0])
    if abs(float(wrap_angle(bearing - r.pose[2]))) < c.max_angle_to_furthest:
        return np.zeros(r.x.shape[0])
    err = np.abs(wrap_angle(np.arctan2(target[1] - r.y, target[0] - r.x) - r.yaw))
    if not c.forward_preference:  # either end of the robot may lead
        err = np.minimum(err, np.pi - err)
    return _score(c, err.mean(axis=1))


def prefer_forward(c: Any, r: Rollouts) -> np.ndarray:
    """Away from the goal: the distance driven backwards."""
    if r.goal_distance < c.threshold_to_consider:
        return np.zeros(r.x.shape[0])
    return _score(c, np.maximum(-r.vx, 0.0).sum(axis=1) * r.dt)


def obstacles(c: Any, r: Rollouts, centre_distance: np.ndarray) -> np.ndarray:
    """Collisions (a pose whose footprint certainly touches: an obstacle inside the inscribed
    circle) cost ``collision_cost``; poses within ``collision_margin_distance`` of that cost
    ``critical_weight`` per metre inside the margin; within ``inflation_radius`` of an obstacle,
    ``repulsion_weight`` per metre (not near the goal, so the robot may reach a goal beside a wall)."""
    inscribed = r.robot.inner_radius
    clearance = centre_distance - inscribed
    collided = (clearance <= 0.0).any(axis=1)
    critical = np.maximum(c.collision_margin_distance - clearance, 0.0).sum(axis=1)
    cost = c.critical_weight * critical
    if r.goal_distance > c.near_goal_distance:
        cost = cost + c.repulsion_weight * np.maximum(c.inflation_radius - centre_distance, 0.0).mean(axis=1)
    if c.cost_power != 1:
        cost = cost ** c.cost_power
    return np.where(collided, c.collision_cost, cost)


#: config attribute -> (critic function). ObstaclesCritic is scored apart (it needs the distances).
CRITICS = {
    "constraint_critic": constraint,
    "goal_critic": goal,
    "goal_angle_critic": goal_angle,
    "path_align_critic": path_align,
    "path_follow_critic": path_follow,
    "path_angle_critic": path_angle,
    "prefer_forward_critic": prefer_forward,
}
