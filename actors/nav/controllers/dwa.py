"""Dynamic Window Approach over the three motion models.

Per step: (1) the dynamic window of velocities reachable within ``control_time_step`` from the
current velocity (acceleration and deceleration limits apart); (2) ``max_linear_samples`` x
``max_angular_samples`` constant-velocity commands (omni robots add lateral samples) rolled out
over ``prediction_horizon`` in closed form, all at once; (3) trajectories whose footprint comes
within ``safety_margin`` of an obstacle are discarded; (4) the rest are scored with the
trajectory costs against the local segment of the reference path, and the best command is
repeated over ``control_horizon``. Differential and omni robots rotate in place first when the
path direction is more than ``rotate_in_place_angle`` away (rotate-then-move).
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from ..costs import TrajectoryCostsWeights, evaluate_costs
from ..kinematics import dynamic_window, feasible_commands, rollout, wrap_angle
from ..robot import RobotConfig, RobotType
from .base import ControlResult, ControlStatus, FollowerConfig, field, robot_state, setters
from .clearance import voxel_downsample
from .detour import detour_reference
from .follower import PathFollower
from .sensors import ObstacleInput, sensor_offset

__all__ = ["DWAConfig", "DWA", "dwa_samples"]


def _vector(value: object, size: int) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size != size or not np.all(np.isfinite(arr)):
        raise ValueError(f"expected {size} finite numbers, got {value!r}")
    return arr


def vec3(value: object) -> np.ndarray:
    """attrs converter: exactly 3 finite numbers (a position)."""
    return _vector(value, 3)


def vec4(value: object) -> np.ndarray:
    """attrs converter: exactly 4 finite numbers (a quaternion x, y, z, w)."""
    return _vector(value, 4)


@attrs.define
class DWAConfig(FollowerConfig):
    """Spec parameters (times in seconds). ``octree_resolution`` (m) is the cell of the voxel
    filter applied to obstacle points before collision checking (half of it, conservatively).
    ``max_num_threads`` is accepted and validated; one step is a handful of vectorized numpy
    calls over all samples at once, so there is no per-thread work split to configure."""

    prediction_horizon: float = field(1.0, 1e-4, 1e6)
    control_horizon: float = field(0.2, 1e-4, 1e6)
    max_linear_samples: int = field(20, 1, 1000, int)
    max_angular_samples: int = field(20, 1, 1000, int)
    sensor_position_to_robot: np.ndarray = attrs.field(factory=lambda: np.zeros(3), converter=vec3, on_setattr=setters, eq=False)
    sensor_rotation_to_robot: np.ndarray = attrs.field(factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]), converter=vec4, on_setattr=setters, eq=False)
    octree_resolution: float = field(0.1, 1e-9, 1e3)
    costs_weights: TrajectoryCostsWeights = attrs.field(factory=TrajectoryCostsWeights)
    max_num_threads: int = field(1, 1, 100, int)

    @costs_weights.validator
    def _check_weights(self, attribute, value) -> None:
        if not isinstance(value, TrajectoryCostsWeights):
            raise TypeError(f"DWAConfig.costs_weights: expected TrajectoryCostsWeights, got {type(value).__name__}")

    @property
    def horizon_steps(self) -> int:
        return max(1, int(round(self.prediction_horizon / self.control_time_step)))

    @property
    def control_steps(self) -> int:
        return max(1, min(self.horizon_steps, int(round(self.control_horizon / self.control_time_step))))


def dwa_samples(robot: RobotConfig, velocity: np.ndarray, dt: float, n_linear: int, n_angular: int) -> np.ndarray:
    """Command samples (N, 3) spanning the dynamic window (feasible for the motion model)."""
    win = dynamic_window(robot, velocity, dt)
    vx = np.linspace(win[0, 0], win[0, 1], n_linear)
    om = np.linspace(win[2, 0], win[2, 1], n_angular)
    if robot.model_type is RobotType.OMNI:
        vy = np.linspace(win[1, 0], win[1, 1], max(3, n_linear // 4))
    else:
        vy = np.zeros(1)
    grid = np.stack(np.meshgrid(vx, vy, om, indexing="ij"), axis=-1).reshape(-1, 3)
    return feasible_commands(robot, grid)


class DWA(PathFollower):
    config: DWAConfig

    def __init__(self, robot: RobotConfig, config: DWAConfig | None = None) -> None:
        super().__init__(robot, config or DWAConfig())
        self.sensor_pose = sensor_offset(self.config.sensor_position_to_robot, self.config.sensor_rotation_to_robot)
        self._detour_side = 1.0  # left first on a tie; then sticky (see _local_segment)

    def _local_segment(self, obstacles: np.ndarray) -> np.ndarray:
        """The part of the reference path the costs compare against: the next
        ``max_vel * prediction_horizon`` metres, detoured around blocking obstacles."""
        assert self.path is not None and self.progress is not None
        robot = self.robot
        reach = robot.ctrl_vx_limits.max_vel * self.config.prediction_horizon + robot.radius
        i0 = self.progress.index
        stop = self.progress.point_ahead(reach) + 1
        far = self.progress.point_ahead(reach + 4.0 * robot.radius + 1.0) + 1
        seg, self._detour_side = detour_reference(
            self.path.points[i0:far], self.path.yaw[i0:far], self.path.s[i0:far], stop - i0,
            obstacles, robot.radius, self.config.safety_margin, self._detour_side)
        return seg

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        self.no_other_inputs(inputs)
        pose, velocity = robot_state(pose, velocity)
        if self.progress is None:
            return self._no_path(pose)
        self.progress.update(pose)
        if self.goal_reached(pose):
            return self._done(pose)
        cfg = self.config
        dt = cfg.control_time_step
        obs = voxel_downsample(self.world_obstacles(pose, obstacles), 0.5 * cfg.octree_resolution)
        segment = self._local_segment(obs)
        # Rotate-then-move: align with the direction of the path a little ahead first.
        ahead = segment[min(len(segment) - 1, max(1, len(segment) // 3))]
        direction = math.atan2(ahead[1] - pose[1], ahead[0] - pose[0]) if len(segment) > 1 else pose[2]
        heading = float(wrap_angle(pose[2] - direction))
        if self.needs_rotation(heading):
            target = self.rotate_command(heading)
            cmds, plan = self.plan(pose, velocity, target[None], cfg.control_steps)
            return ControlResult(cmds[0], plan[0], ControlStatus.ROTATING, {"heading_error": heading})
        samples = dwa_samples(self.robot, velocity, dt, cfg.max_linear_samples, cfg.max_angular_samples)
        trajectories = rollout(pose, samples, dt, cfg.horizon_steps)
        # Downsampling can hide a point up to one cell diagonal away: stay conservative.
        clear = self.clearances(trajectories, obs) - 0.5 * cfg.octree_resolution * math.sqrt(2.0)
        here = self.clearances(np.repeat(pose[None, None], 2, axis=1), obs)[0] - 0.5 * cfg.octree_resolution * math.sqrt(2.0)
        admissible = clear > min(cfg.safety_margin, here - 1e-3)
        if not np.any(admissible):
            brake, plan = self.plan(pose, velocity, np.zeros((1, 3)), cfg.control_steps)
            return ControlResult(brake[0], plan[0], ControlStatus.BLOCKED, {"clearance": float(clear.max())})
        idx = np.nonzero(admissible)[0]
        trajs = trajectories[idx]
        vel = np.broadcast_to(samples[idx][:, None, :], (idx.size, cfg.horizon_steps, 3))
        lim = (self.robot.ctrl_vx_limits, self.robot.ctrl_vy_limits, self.robot.ctrl_omega_limits)
        costs = evaluate_costs(
            cfg.costs_weights, trajs, vel,
            reference_path=segment, goal=segment[-1],
            obstacle_min_distance=np.where(np.isinf(clear[idx]), np.inf, clear[idx] + self.robot.radius),
            robot_radius=self.robot.radius, dt=dt,
            acc_limits=np.array([axis.max_acc for axis in lim]), initial_velocity=velocity,
            # Progress relative to what the horizon can cover: measured against the whole
            # segment, one step of progress from standstill is too small to outweigh the
            # obstacle term and the robot parks in front of obstacles it could pass.
            goal_normalizer=max(self.robot.ctrl_vx_limits.max_vel * cfg.prediction_horizon, 0.1),
        )
        best = int(np.argmin(costs.total))
        command = samples[idx[best]]
        return ControlResult(
            np.repeat(command[None], cfg.control_steps, axis=0), trajs[best], ControlStatus.RUNNING,
            {"cost": float(costs.total[best]), "samples": int(samples.shape[0]),
             "admissible": int(idx.size), "clearance": float(clear[idx[best]])},
        )
