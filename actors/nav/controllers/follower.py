"""Base class of the path-following controllers: path, progress, goal and speed profile."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..kinematics import integrate_sequence, ramp_commands, wrap_angle
from ..robot import RobotConfig, RobotType
from .base import ControlResult, ControlStatus, FollowerConfig
from .clearance import nearby_obstacles, trajectory_min_clearance, warm_up
from .path import PathProgress, ReferencePath
from .sensors import ObstacleInput, obstacle_points

__all__ = ["PathFollower"]

TURN_HYSTERESIS = 0.35  # rad (20 degrees) either side of +-pi where an in-place turn keeps its way


class PathFollower:
    """What the Controller component asks of a path-following algorithm, as Nav2's
    ``nav2_core::Controller`` is for its controller server: ``set_path`` then ``compute`` once per
    control step. It holds the reference path and the robot; subclasses implement ``compute``.

    Capabilities are declared here, with the defaults of a plain follower, and read directly by
    the component (never probed): a subclass that has one overrides the attribute.
    """

    config: FollowerConfig
    #: Where a ``scan`` given to ``compute`` is mounted on the robot (x, y, yaw).
    scan_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: ``compute`` takes the laser ``scan`` as well, to track moving obstacles in it.
    tracks_movers: bool = False
    #: The last step stood aside or slowed for a moving obstacle: waiting, not stalled.
    waiting: bool = False

    def __init__(self, robot: RobotConfig, config: FollowerConfig) -> None:
        if not isinstance(robot, RobotConfig):
            raise TypeError(f"robot: expected a RobotConfig, got {type(robot).__name__}")
        self.robot = robot
        self.config = config
        warm_up()  # clearance's k-d tree: imported while the controller is built, not mid-step
        self.path: ReferencePath | None = None
        self.progress: PathProgress | None = None
        self.sensor_pose = (0.0, 0.0, 0.0)
        self._turn = 0.0  # the way the last in-place rotation turned (+1 left, -1 right, 0 none yet)

    # -- path -------------------------------------------------------------------------
    def set_path(self, path: np.ndarray) -> None:
        """Start tracking a new world-frame path (R, 2) or (R, 3)."""
        self.path = ReferencePath(path, spacing=self.config.path_resolution)
        # Progress may jump ahead by what the robot can drive in a few seconds (a detour
        # rejoining the path further on), but never to a far branch of a U-turn or loop.
        reach = max(1.0, 4.0 * self.robot.ctrl_vx_limits.max_vel)
        self.progress = PathProgress(self.path, search_ahead=reach)

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        """One control step from the robot's ``pose`` (world) and body ``velocity``, with the
        obstacles of this step (robot frame, mounted at ``sensor_pose``)."""
        raise NotImplementedError(f"{type(self).__name__} does not implement compute")

    def no_other_inputs(self, inputs: dict[str, Any]) -> None:
        """For ``compute``: extra ``inputs`` come only with a capability that asks for them (as
        ``scan`` with ``tracks_movers``); any other is an error, as an unknown keyword is."""
        if inputs:
            raise TypeError(f"{type(self).__name__}.compute() got unexpected inputs: {', '.join(sorted(inputs))}")

    def goal_reached(self, pose: np.ndarray) -> bool:
        return self.progress is not None and self.progress.goal_reached(pose, self.config.goal_dist_tolerance)

    # -- helpers ----------------------------------------------------------------------
    def world_obstacles(self, pose: np.ndarray, obstacles: ObstacleInput) -> np.ndarray:
        """Obstacle input (robot frame) -> (M, 2) world points."""
        pts = obstacle_points(obstacles, self.sensor_pose)
        if pts.shape[0] == 0:
            return pts
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.stack([pose[0] + c * pts[:, 0] - s * pts[:, 1], pose[1] + s * pts[:, 0] + c * pts[:, 1]], axis=-1)

    def desired_speed(self) -> float:
        """Cruise speed, reduced near the goal so that braking at half max_decel stops on it."""
        assert self.progress is not None
        vmax = self.robot.ctrl_vx_limits.max_vel
        remaining = max(self.progress.remaining, 0.0)
        return min(vmax, math.sqrt(2.0 * 0.5 * self.robot.ctrl_vx_limits.max_decel * remaining) + 0.05)

    def rotate_command(self, heading_error: float) -> np.ndarray:
        """In-place rotation that removes ``heading_error`` (rad) without overshoot. With the
        target nearly behind (within ``TURN_HYSTERESIS`` of +-pi) it keeps turning the way it
        last turned: there the sign of the wrapped error flips with every centimetre a re-plan
        moves the path, and a robot that followed it turned back and forth in place for good
        (seen in `emos bench costmap --drive`, a new KPIECE1 path every second)."""
        lim = self.robot.ctrl_omega_limits
        # The largest speed from which braking still stops within the remaining angle.
        w = min(lim.max_vel, math.sqrt(2.0 * lim.max_decel * abs(heading_error)))
        turn = -math.copysign(1.0, heading_error)
        if self._turn != 0.0 and abs(heading_error) > math.pi - TURN_HYSTERESIS:
            turn = self._turn
        self._turn = turn
        return np.array([0.0, 0.0, turn * w])

    def needs_rotation(self, heading_error: float) -> bool:
        return self.robot.model_type is not RobotType.ACKERMANN and abs(heading_error) > self.config.rotate_in_place_angle

    def plan(self, pose: np.ndarray, velocity: np.ndarray, targets: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """Ramped command sequences (N, steps, 3) towards targets and their poses."""
        cmds = ramp_commands(self.robot, velocity, targets, self.config.control_time_step, steps)
        return cmds, integrate_sequence(pose, cmds, self.config.control_time_step)

    def clearances(self, poses: np.ndarray, obstacles_world: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
        """Minimum footprint clearance per candidate trajectory (N,).

        ``valid`` (N, P) masks the poses that count (e.g. per-candidate horizons).
        """
        if obstacles_world.shape[0] == 0:
            return np.full(poses.shape[0], np.inf)
        reach = float(np.max(np.hypot(poses[..., 0] - poses[0, 0, 0], poses[..., 1] - poses[0, 0, 1]))) + self.robot.radius + 0.5
        near = nearby_obstacles(obstacles_world, poses[0, 0, :2], reach)
        if near.shape[0] == 0:
            return np.full(poses.shape[0], np.inf)
        # The start pose is where the robot already is: judge only where it is going.
        return trajectory_min_clearance(self.robot, poses[:, 1:], near, None if valid is None else valid[:, 1:])

    def _no_path(self, pose: np.ndarray) -> ControlResult:
        return ControlResult.stop(pose, ControlStatus.NO_PATH)

    def _done(self, pose: np.ndarray) -> ControlResult:
        return ControlResult.stop(pose, ControlStatus.GOAL_REACHED)

    @staticmethod
    def heading_error(yaw: float, target_yaw: float) -> float:
        return float(wrap_angle(yaw - target_yaw))
