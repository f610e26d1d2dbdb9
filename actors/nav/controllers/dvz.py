"""Deformable Virtual Zone (DVZ): a reactive controller around an internal path follower.

The robot carries a virtual zone, an ellipse ``robot radius + min_front_margin`` long in front
and ``side_margin_width_ratio`` times that wide. Obstacles inside it deform it: for each
direction alpha the deformed radius is ``d_h(alpha) = min(R(alpha), range(alpha))``. From the
deformation we get the intrusion intensity ``I_D = mean((R - d_h) / R)`` (the spec's integral)
and the deformation angle ``Theta_D``, the deformation-weighted mean direction (taken as a
circular mean so that intrusions straddling +-pi do not average to 0). The command of the
internal Stanley-type follower (``heading_gain``, ``cross_track_gain``) is then corrected by
the *depth* of the deepest intrusion, ``D = max((R - d_h) / R)``, in direction ``Theta_D``
relative to the direction of travel (``ahead = max(cos, 0)``):

* linear: ``v = v_ref * (1 - K_linear * D * ahead)``, slowing down for frontal intrusion;
* angular: ``omega = omega_ref + K_angular * K_I * D * ahead * turn``, ``turn`` pointing away
  from ``Theta_D`` (a sticky side when the intrusion is dead ahead, so it never freezes);
* omni robots also sidestep with ``K_I * D * ahead * turn * max_vy``.

Why ``D`` and not ``I_D`` as the gain: ``I_D`` averages over all directions, so a single
post 0.3 m away in a 1.2 m zone gives ``I_D`` of about 0.02 and, with the default gains, a
reaction far too weak to steer around it; ``I_D`` and ``Theta_D`` are still reported in the
result's info. A last check rolls the command out briefly and stops translation if it would
touch anything.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.geometry import wrap_angle

from ..robot import RobotConfig, RobotType
from .base import ControlResult, ControlStatus, FollowerConfig, field, robot_state
from .follower import PathFollower
from .sensors import ObstacleInput, obstacle_points
from .stanley import Stanley, StanleyConfig

__all__ = ["DVZConfig", "DVZ", "deformation"]


@attrs.define
class DVZConfig(FollowerConfig):
    min_front_margin: float = field(1.0, 0.0, 1e2)
    K_linear: float = field(1.0, 0.1, 10.0)
    K_angular: float = field(1.0, 0.1, 10.0)
    K_I: float = field(5.0, 0.1, 10.0)
    side_margin_width_ratio: float = field(1.0, 1e-2, 1e2)
    heading_gain: float = field(0.7, 0.0, 1e2)
    cross_track_gain: float = field(1.5, 0.0, 1e2)


def deformation(points: np.ndarray, front: float, side: float, bins: int = 72) -> tuple[float, float, np.ndarray]:
    """(I_D, Theta_D, per-bin deformation) of an ellipse zone by robot-frame points (M, 2)."""
    alpha = -math.pi + (np.arange(bins) + 0.5) * (2 * math.pi / bins)
    radius = front * side / np.sqrt((side * np.cos(alpha)) ** 2 + (front * np.sin(alpha)) ** 2)
    d_h = radius.copy()
    if points.shape[0]:
        ang = np.arctan2(points[:, 1], points[:, 0])
        dist = np.hypot(points[:, 0], points[:, 1])
        idx = np.clip(((ang + math.pi) / (2 * math.pi) * bins).astype(np.int64), 0, bins - 1)
        np.minimum.at(d_h, idx, dist)
    w = (radius - d_h) / radius
    intensity = float(w.mean())
    if intensity <= 0.0:
        return 0.0, 0.0, w
    theta = math.atan2(float(np.sum(w * np.sin(alpha))), float(np.sum(w * np.cos(alpha))))
    return intensity, theta, w


class DVZ(PathFollower):
    config: DVZConfig

    def __init__(self, robot: RobotConfig, config: DVZConfig | None = None) -> None:
        super().__init__(robot, config or DVZConfig())
        cfg = self.config
        self._follower = Stanley(robot, StanleyConfig(
            control_time_step=cfg.control_time_step, goal_dist_tolerance=cfg.goal_dist_tolerance,
            path_resolution=cfg.path_resolution, rotate_in_place_angle=cfg.rotate_in_place_angle,
            heading_gain=cfg.heading_gain, cross_track_gain=cfg.cross_track_gain))
        self._side = 1.0

    def set_path(self, path: np.ndarray) -> None:
        super().set_path(path)
        self._follower.set_path(path)
        self.progress = self._follower.progress

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        self.no_other_inputs(inputs)
        pose, velocity = robot_state(pose, velocity)
        if self.progress is None:
            return self._no_path(pose)
        cfg = self.config
        robot = self.robot
        local = obstacle_points(obstacles, self.sensor_pose)
        front = robot.radius + cfg.min_front_margin
        intensity, theta, w_bins = deformation(local, front, front * cfg.side_margin_width_ratio)
        # While the zone is deformed the follower must not rotate back towards the path in
        # place: that undoes the avoidance turn and the two cancel out into a standstill.
        self._follower.config.rotate_in_place_angle = math.pi if intensity > 0.0 else cfg.rotate_in_place_angle
        nominal = self._follower.compute(pose, velocity)
        if nominal.status is ControlStatus.GOAL_REACHED:
            return nominal
        v_ref, vy_ref, w_ref = (float(c) for c in nominal.command)
        if intensity > 0.0:
            # I_D averages over all directions, so a small obstacle barely moves it; the
            # reaction is scaled by the deepest intrusion, in the direction Theta_D.
            depth = float(w_bins.max())
            # Judge the intrusion against the direction of travel (an omni robot may move
            # sideways), not against the heading.
            moving = math.atan2(vy_ref, v_ref) if abs(v_ref) + abs(vy_ref) > 1e-6 else 0.0
            rel = wrap_angle(theta - moving)
            if abs(rel) > 0.35:  # clear side: turn away from it and remember that side
                self._side = -math.copysign(1.0, rel)
            ahead = max(math.cos(rel), 0.0)
            turn = self._side * max(abs(math.sin(rel)), ahead)
            slow = max(0.0, 1.0 - cfg.K_linear * depth * ahead)
            w = w_ref + cfg.K_angular * cfg.K_I * depth * turn * ahead
            v, vy = v_ref * slow, vy_ref * slow
            if robot.model_type is RobotType.OMNI:
                # Holonomic: also sidestep, perpendicular to the direction of travel.
                push = cfg.K_I * depth * turn * ahead * robot.ctrl_vy_limits.max_vel
                v -= push * math.sin(moving)
                vy += push * math.cos(moving)
            target = np.array([v, vy, w])
        else:
            target = np.array([v_ref, vy_ref, w_ref])
        status = nominal.status if intensity == 0.0 else ControlStatus.AVOIDING
        cmds, plans = self.plan(pose, velocity, np.vstack([target, target * [0, 0, 1], np.zeros(3)]), 5)
        obs_world = self.world_obstacles(pose, obstacles)
        clear = self.clearances(plans, obs_world)
        here = self.clearances(np.repeat(pose[None, None], 2, axis=1), obs_world)[0]
        ok = np.nonzero(clear > min(cfg.safety_margin, here - 1e-3))[0]
        choice = int(ok[0]) if ok.size else 2
        if choice > 0:
            status = ControlStatus.BLOCKED
        return ControlResult(cmds[choice][:1], plans[choice], status,
                             {"intrusion": intensity, "deformation_angle": theta})
