"""Stanley steering: heading error plus arctan of the front-axle cross-track error.

``delta = heading_gain * psi_e + atan(cross_track_gain * e / max(v, cross_track_min_linear_vel))``

Ackermann robots turn ``delta`` into ``omega = v tan(delta) / wheel_base``. Differential and
omni robots use the same law on a virtual wheel base (their footprint diameter) and the
rotate-then-move policy: when the heading error exceeds ``rotate_in_place_angle`` they rotate
in place until it is below ``max_angle_error``. Omni robots also cancel the cross-track error
with lateral velocity. Stanley is a pure path follower: it does not look at obstacles.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from ..kinematics import limit_command_change, wrap_angle
from ..robot import RobotConfig, RobotType
from .base import ControlResult, ControlStatus, FollowerConfig, field, robot_state
from .follower import PathFollower
from .sensors import ObstacleInput

__all__ = ["StanleyConfig", "Stanley"]


@attrs.define
class StanleyConfig(FollowerConfig):
    heading_gain: float = field(0.7, 0.0, 1e2)
    cross_track_min_linear_vel: float = field(0.05, 1e-4, 1e2)
    min_angular_vel: float = field(0.01, 0.0, 1e9)
    cross_track_gain: float = field(1.5, 0.0, 1e2)
    max_angle_error: float = field(math.pi / 16, 1e-9, math.pi)
    max_distance_error: float = field(0.1, 1e-9, 1e9)


class Stanley(PathFollower):
    config: StanleyConfig

    def __init__(self, robot: RobotConfig, config: StanleyConfig | None = None) -> None:
        super().__init__(robot, config or StanleyConfig())
        self._rotating = False

    def _front_axle(self, pose: np.ndarray) -> np.ndarray:
        half = 0.5 * self.robot.wheel_base
        return np.array([pose[0] + half * math.cos(pose[2]), pose[1] + half * math.sin(pose[2]), pose[2]])

    def steering(self, pose: np.ndarray, speed: float) -> tuple[float, float, float]:
        """(steering angle delta, cross-track error e, heading error psi_e) at the front axle."""
        assert self.progress is not None
        lateral, heading = self.progress.cross_track(self._front_axle(pose))
        psi_e = -heading  # path yaw - robot yaw
        e = -lateral  # positive when the path is to the robot's left
        cfg = self.config
        delta = cfg.heading_gain * psi_e + math.atan2(cfg.cross_track_gain * e, max(abs(speed), cfg.cross_track_min_linear_vel))
        return float(delta), float(e), float(psi_e)

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        """One control step (``obstacles`` is accepted for a uniform interface and ignored)."""
        self.no_other_inputs(inputs)
        pose, velocity = robot_state(pose, velocity)
        if self.progress is None:
            return self._no_path(pose)
        # Track progress at the front axle: that is where Stanley measures its errors.
        self.progress.update(self._front_axle(pose))
        if self.goal_reached(pose):
            return self._done(pose)
        cfg = self.config
        robot = self.robot
        v = self.desired_speed()
        delta, e, psi_e = self.steering(pose, float(velocity[0]))
        status = ControlStatus.RUNNING
        if robot.model_type is not RobotType.ACKERMANN:
            # Far from the path, align with the way back to it rather than with its tangent.
            align = psi_e
            if abs(e) > cfg.max_distance_error:
                assert self.path is not None
                target = self.path.points[self.progress.point_ahead(max(abs(e), 0.3))]
                align = float(wrap_angle(math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2]))
            if abs(align) > cfg.rotate_in_place_angle:
                self._rotating = True
            elif abs(align) < cfg.max_angle_error:
                self._rotating = False
            if self._rotating:
                target = self.rotate_command(-align)
                status = ControlStatus.ROTATING
            else:
                target = self._drive(v, delta, e, psi_e)
        else:
            target = self._drive(v, delta, e, psi_e)
        if abs(target[2]) < cfg.min_angular_vel:
            target[2] = 0.0
        cmd = limit_command_change(robot, velocity, target, cfg.control_time_step)
        plan = self.plan(pose, velocity, target[None], 10)[1][0]
        return ControlResult(cmd[None], plan, status, {"cross_track_error": e, "heading_error": psi_e})

    def _drive(self, v: float, delta: float, e: float, psi_e: float) -> np.ndarray:
        robot = self.robot
        if robot.model_type is RobotType.ACKERMANN:
            max_steer = robot.ctrl_omega_limits.max_steer
            delta = float(np.clip(delta, -max_steer, max_steer))
            return np.array([v, 0.0, v * math.tan(delta) / robot.wheel_base])
        base = 2.0 * robot.radius
        delta = float(np.clip(delta, -1.2, 1.2))
        w = v * math.tan(delta) / base
        if robot.model_type is RobotType.OMNI:
            # Holonomic: correct the offset sideways instead of only by turning.
            vy = float(np.clip(self.config.cross_track_gain * e, -robot.ctrl_vy_limits.max_vel, robot.ctrl_vy_limits.max_vel))
            return np.array([v, vy, self.config.heading_gain * psi_e / max(self.config.control_time_step * 5, 1e-3)])
        return np.array([v, 0.0, w])
