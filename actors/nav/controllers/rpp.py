"""Regulated Pure Pursuit, with Nav2's parameters (nav2_regulated_pure_pursuit_controller).

Pure pursuit towards a carrot ``lookahead`` metres along the path, with the linear speed
regulated the ways Nav2's RPP does:

* curvature: on arcs tighter than ``regulated_linear_scaling_min_radius`` the speed scales down
  with the radius (not below ``regulated_linear_scaling_min_speed``);
* proximity: within ``cost_scaling_dist`` of an obstacle the speed scales with the distance
  (times ``cost_scaling_gain``); Nav2 reads the distance from the inflated costmap, we from
  this step's obstacle points;
* approach: within ``approach_velocity_scaling_dist`` of the goal the speed scales with the
  distance left, not below ``min_approach_linear_velocity``;
* acceleration: the robot's limits.

``use_rotate_to_heading``: when the carrot is more than ``rotate_to_heading_min_angle`` off
the robot's heading, rotate in place at up to ``rotate_to_heading_angular_vel`` first.
``use_collision_detection``: the arc is rolled out for ``max_allowed_time_to_collision_up_to_carrot``
seconds (at least to the carrot) with the footprint; if it touches, the robot stops (BLOCKED),
as Nav2's RPP refuses the command ("collision ahead").
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from ..kinematics import to_robot_frame
from ..robot import RobotConfig, RobotType
from .base import ControlResult, ControlStatus, FollowerConfig, field, robot_state
from .follower import PathFollower
from .sensors import ObstacleInput

__all__ = ["RegulatedPurePursuitConfig", "RegulatedPurePursuit"]


@attrs.define
class RegulatedPurePursuitConfig(FollowerConfig):
    """Nav2's RPP parameters and defaults (``desired_linear_vel`` None: the robot's max speed)."""

    desired_linear_vel: float | None = attrs.field(default=None)
    lookahead_dist: float = field(0.6, 1e-3, 1e2)
    min_lookahead_dist: float = field(0.3, 1e-3, 1e2)
    max_lookahead_dist: float = field(0.9, 1e-3, 1e2)
    lookahead_time: float = field(1.5, 1e-3, 1e2)
    use_velocity_scaled_lookahead_dist: bool = attrs.field(default=False, converter=bool)
    rotate_to_heading_angular_vel: float = field(1.8, 1e-3, 1e2)
    use_rotate_to_heading: bool = attrs.field(default=True, converter=bool)
    rotate_to_heading_min_angle: float = field(0.785, 0.0, math.pi)
    min_approach_linear_velocity: float = field(0.05, 0.0, 1e2)
    approach_velocity_scaling_dist: float = field(0.6, 0.0, 1e2)
    use_regulated_linear_velocity_scaling: bool = attrs.field(default=True, converter=bool)
    regulated_linear_scaling_min_radius: float = field(0.9, 1e-3, 1e3)
    regulated_linear_scaling_min_speed: float = field(0.25, 0.0, 1e2)
    use_cost_regulated_linear_velocity_scaling: bool = attrs.field(default=True, converter=bool)
    cost_scaling_dist: float = field(0.6, 1e-3, 1e2)
    cost_scaling_gain: float = field(1.0, 0.0, 1e2)
    use_collision_detection: bool = attrs.field(default=True, converter=bool)
    max_allowed_time_to_collision_up_to_carrot: float = field(1.0, 0.0, 1e2)

    def __attrs_post_init__(self) -> None:
        if self.desired_linear_vel is not None and not (isinstance(self.desired_linear_vel, (int, float)) and 0 < self.desired_linear_vel < 1e2):
            raise ValueError(f"RegulatedPurePursuitConfig.desired_linear_vel: expected None (the robot's max speed) or a speed in (0, 100) m/s, got {self.desired_linear_vel!r}")
        if self.min_lookahead_dist > self.max_lookahead_dist:
            raise ValueError(f"RegulatedPurePursuitConfig: min_lookahead_dist ({self.min_lookahead_dist}) must not exceed max_lookahead_dist ({self.max_lookahead_dist})")


class RegulatedPurePursuit(PathFollower):
    config: RegulatedPurePursuitConfig

    def __init__(self, robot: RobotConfig, config: RegulatedPurePursuitConfig | None = None) -> None:
        super().__init__(robot, config or RegulatedPurePursuitConfig())
        # An omni robot is driven as a differential one (vy = 0), as Nav2's RPP does.

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        self.no_other_inputs(inputs)
        pose, velocity = robot_state(pose, velocity)
        if self.progress is None or self.path is None:
            return self._no_path(pose)
        self.progress.update(pose)
        if self.goal_reached(pose):
            return self._done(pose)
        cfg, robot = self.config, self.robot
        speed = float(velocity[0])
        lookahead = cfg.lookahead_dist
        if cfg.use_velocity_scaled_lookahead_dist:
            lookahead = min(max(abs(speed) * cfg.lookahead_time, cfg.min_lookahead_dist), cfg.max_lookahead_dist)
        carrot = self.path.points[self.progress.point_ahead(lookahead)]
        local = to_robot_frame(pose, carrot)
        xt, yt = float(local[0]), float(local[1])
        dt = cfg.control_time_step
        obs = self.world_obstacles(pose, obstacles)
        angle = math.atan2(yt, xt)
        if cfg.use_rotate_to_heading and robot.model_type is not RobotType.ACKERMANN and abs(angle) > cfg.rotate_to_heading_min_angle:
            return self._rotate(pose, velocity, angle, obs)
        dist2 = max(xt * xt + yt * yt, 1e-9)
        curvature = 2.0 * yt / dist2
        if robot.model_type is RobotType.ACKERMANN:
            curvature = float(np.clip(curvature, -robot.max_curvature, robot.max_curvature))
        v = self._regulated_speed(curvature, obs, pose)
        lim = robot.ctrl_vx_limits
        v = min(max(v, speed - lim.max_decel * dt), speed + lim.max_acc * dt)  # acceleration limits, from the measured speed
        w_max = robot.ctrl_omega_limits.max_vel
        if abs(v * curvature) > w_max:  # keep the arc, slow down to the angular limit
            v = w_max / abs(curvature)
        cmd = np.array([v, 0.0, v * curvature])
        horizon = max(cfg.max_allowed_time_to_collision_up_to_carrot, math.sqrt(dist2) / max(abs(v), 1e-3))
        steps = max(1, int(math.ceil(horizon / dt)))
        cmds, poses = self.plan(pose, velocity, cmd[None], steps)
        clear = self.clearances(poses, obs)[0] if cfg.use_collision_detection else math.inf
        if clear <= 0.0:
            return ControlResult.stop(pose, ControlStatus.BLOCKED, clearance=float(clear), reason="collision ahead on the arc to the carrot")
        return ControlResult(cmds[0], poses[0], ControlStatus.RUNNING,
                             {"clearance": float(clear), "lookahead": lookahead, "curvature": curvature, "tracked_index": self.progress.index})

    def _regulated_speed(self, curvature: float, obs: np.ndarray, pose: np.ndarray) -> float:
        cfg = self.config
        assert self.progress is not None
        v = float(cfg.desired_linear_vel) if cfg.desired_linear_vel is not None else self.robot.ctrl_vx_limits.max_vel
        regulated = v
        if cfg.use_regulated_linear_velocity_scaling and abs(curvature) > 1e-9:
            radius = 1.0 / abs(curvature)
            if radius < cfg.regulated_linear_scaling_min_radius:
                regulated = v * radius / cfg.regulated_linear_scaling_min_radius
        if cfg.use_cost_regulated_linear_velocity_scaling and obs.shape[0]:
            here = float(self.clearances(np.repeat(pose[None, None], 2, axis=1), obs)[0])
            if here < cfg.cost_scaling_dist:
                regulated = min(regulated, v * cfg.cost_scaling_gain * max(here, 0.0) / cfg.cost_scaling_dist)
        if regulated < v:  # a regulated speed never below the floor (unless the approach asks it)
            regulated = max(regulated, cfg.regulated_linear_scaling_min_speed)
        remaining = self.progress.remaining
        if remaining < cfg.approach_velocity_scaling_dist:
            regulated = min(regulated, max(v * remaining / cfg.approach_velocity_scaling_dist, cfg.min_approach_linear_velocity))
        return min(regulated, v)

    def _rotate(self, pose: np.ndarray, velocity: np.ndarray, angle: float, obs: np.ndarray) -> ControlResult:
        """Rotate in place towards the carrot, braking in time to stop on it, the footprint
        checked over the rotation (a rectangle's corners sweep outside its inscribed circle)."""
        cfg, lim = self.config, self.robot.ctrl_omega_limits
        dt = cfg.control_time_step
        w_max = min(cfg.rotate_to_heading_angular_vel, lim.max_vel, math.sqrt(2.0 * lim.max_decel * abs(angle)))
        w_now = float(velocity[2])
        w = math.copysign(min(w_max, abs(w_now) + lim.max_acc * dt), angle)
        steps = max(1, int(math.ceil(abs(angle) / max(abs(w), 1e-3) / dt)))
        cmds, poses = self.plan(pose, velocity, np.array([[0.0, 0.0, w]]), steps)
        clear = self.clearances(poses, obs)[0] if cfg.use_collision_detection else math.inf
        if clear <= 0.0:
            return ControlResult.stop(pose, ControlStatus.BLOCKED, clearance=float(clear), reason="rotating to heading would touch an obstacle")
        return ControlResult(cmds[0], poses[0], ControlStatus.ROTATING, {"clearance": float(clear), "heading_error": angle})
