"""VisionRGBDFollower: depth-aware target following with DWA-style obstacle-aware rollouts.

1. The detection box is back-projected with the depth image (median of the valid depths in
   the central half of the box, times ``depth_conversion_factor``) and the camera intrinsics
   into the robot frame, then into the world with the robot pose.
2. An alpha-beta filter tracks the target's world position and velocity, so the goal can lead
   a moving target and survives a few missed detections.
3. The goal pose is ``target_distance`` from the target at bearing ``target_orientation``
   (relative to the line of sight), facing the target.
4. Samples of the dynamic window are rolled out over ``prediction_horizon`` steps, those that
   touch obstacles are discarded, and the rest are scored on distance to the goal, facing
   the target, obstacle clearance and smoothness.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from ..costs import TrajectoryCostsWeights, evaluate_costs
from ..kinematics import integrate_sequence, ramp_commands, rollout, wrap_angle
from ..robot import RobotConfig
from .base import ControlResult, ControlStatus, FollowerConfig, field, robot_state, setters
from .clearance import nearby_obstacles, pose_clearance, voxel_downsample, warm_up
from .detour import detour_reference
from .dwa import dwa_samples, vec3, vec4
from .sensors import ObstacleInput, obstacle_points, sensor_offset
from .vision_common import BoundingBox, CameraIntrinsics, TargetSearch, median_depth

__all__ = ["VisionRGBDFollowerConfig", "VisionRGBDFollower", "target_from_depth"]


@attrs.define
class VisionRGBDFollowerConfig(FollowerConfig):
    """``prediction_horizon``, ``control_horizon`` and ``target_search_pause`` are in steps.

    ``target_distance=None`` keeps the distance measured at the first detection.
    ``target_gate`` (m), ``target_max_speed`` (m/s), ``target_gate_misses``: a measurement within
    ``target_gate`` of the tracked target's prediction is the target. One farther than
    ``target_gate + target_max_speed * (time since the last one)`` is not (a false detection, or a
    box whose depth patch hit the wall behind): it is ignored and the prediction followed,
    unless ``target_gate_misses`` measurements in a row disagree, when the tracker starts again
    from the newest (the target really is there). One in between (the target could have walked
    there since it was last seen, after a gap in the detections) is taken once the next
    measurement confirms it (within ``target_gate`` of it): a single false detection after a gap
    is not followed.
    ``camera_rotation_to_robot`` is the quaternion (x, y, z, w) of the camera body frame
    (x forward) on the robot; the optical frame convention (z forward) is applied on top.
    The DWA parameters (samples, sensor pose, ``octree_resolution``, ``costs_weights``,
    ``max_num_threads``) mean what they mean in :class:`DWAConfig`.
    """

    target_distance: float | None = attrs.field(default=None, on_setattr=setters)
    target_orientation: float = field(0.0, -math.pi, math.pi)
    prediction_horizon: int = field(10, 1, 1000, int)
    control_horizon: int = field(2, 1, 1000, int)
    target_search_timeout: float = field(30.0, 0.0, 1e6)
    target_search_pause: float = field(2, 0, 1e6)
    enable_search: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool), on_setattr=setters)
    depth_conversion_factor: float = field(1e-3, 1e-9, 1e3)
    target_gate: float = field(0.5, 0.0, 1e3)
    target_max_speed: float = field(2.0, 0.0, 1e3)
    target_gate_misses: int = field(5, 1, 10_000, int)
    camera_position_to_robot: np.ndarray = attrs.field(factory=lambda: np.zeros(3), converter=vec3, on_setattr=setters, eq=False)
    camera_rotation_to_robot: np.ndarray = attrs.field(factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]), converter=vec4, on_setattr=setters, eq=False)
    max_linear_samples: int = field(20, 1, 1000, int)
    max_angular_samples: int = field(20, 1, 1000, int)
    # DWA parameters the RGB-D follower shares (same names and defaults as DWAConfig).
    sensor_position_to_robot: np.ndarray = attrs.field(factory=lambda: np.zeros(3), converter=vec3, on_setattr=setters, eq=False)
    sensor_rotation_to_robot: np.ndarray = attrs.field(factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]), converter=vec4, on_setattr=setters, eq=False)
    octree_resolution: float = field(0.1, 1e-9, 1e3)
    max_num_threads: int = field(1, 1, 100, int)
    costs_weights: TrajectoryCostsWeights = attrs.field(factory=TrajectoryCostsWeights)

    @target_distance.validator
    def _check_distance(self, attribute, value) -> None:
        if value is not None and not (isinstance(value, (int, float)) and 0.0 < value < 1e3):
            raise ValueError(f"VisionRGBDFollowerConfig.target_distance: expected None or a distance "
                             f"in (0, 1e3) m, got {value!r}")


def target_from_depth(box: BoundingBox, depth_image: np.ndarray, intrinsics: CameraIntrinsics,
                      depth_conversion_factor: float) -> np.ndarray | None:
    """Target centre in the camera *body* frame (x forward, y left, z up), or None.

    Uses the median of the valid depths (finite, > 0) in the central half of the box, which
    ignores background pixels at the box edges and depth holes.
    """
    u0, v0 = box.center
    raw = median_depth(depth_image, u0, v0, 0.25 * box.width, 0.25 * box.height)
    if raw is None:
        return None
    z = raw * depth_conversion_factor
    optical = intrinsics.back_project(u0, v0, z)
    # Optical (x right, y down, z forward) -> body (x forward, y left, z up).
    return np.array([optical[2], -optical[0], -optical[1]])


class _AlphaBeta:
    """Constant-velocity alpha-beta filter on the target's world (x, y)."""

    def __init__(self, alpha: float = 0.6, beta: float = 0.2) -> None:
        self.alpha, self.beta = alpha, beta
        self.position: np.ndarray | None = None
        self.velocity = np.zeros(2)

    def predict(self, dt: float) -> np.ndarray | None:
        if self.position is not None:
            self.position = self.position + self.velocity * dt
        return self.position

    def update(self, measured: np.ndarray, dt: float) -> np.ndarray:
        if self.position is None:
            self.position = measured.copy()
            return self.position
        residual = measured - self.position
        self.position = self.position + self.alpha * residual
        self.velocity = self.velocity + (self.beta / dt) * residual
        return self.position


class VisionRGBDFollower:
    def __init__(self, robot: RobotConfig, intrinsics: CameraIntrinsics,
                 config: VisionRGBDFollowerConfig | None = None) -> None:
        self.robot = robot
        self.intrinsics = intrinsics
        self.config = config or VisionRGBDFollowerConfig()
        warm_up()  # clearance's k-d tree: imported while the controller is built, not mid-step
        cfg = self.config
        self.camera_pose = sensor_offset(cfg.camera_position_to_robot, cfg.camera_rotation_to_robot)
        self.search = TargetSearch(robot, cfg.control_time_step, cfg.target_search_pause,
                                   cfg.target_search_timeout, cfg.enable_search)
        self.tracker = _AlphaBeta()
        self.distance: float | None = cfg.target_distance
        self.sensor_pose = sensor_offset(cfg.sensor_position_to_robot, cfg.sensor_rotation_to_robot)
        self._detour_side = 1.0
        self._since_measurement = 0.0
        self._gate_misses = 0  # measurements in a row outside the gate
        self._candidate: np.ndarray | None = None  # a far but reachable measurement waiting to be confirmed

    def _target_world(self, box: BoundingBox, depth: np.ndarray, pose: np.ndarray) -> np.ndarray | None:
        body = target_from_depth(box, depth, self.intrinsics, self.config.depth_conversion_factor)
        if body is None:
            return None
        cx, cy, cyaw = self.camera_pose
        rx = cx + math.cos(cyaw) * body[0] - math.sin(cyaw) * body[1]
        ry = cy + math.sin(cyaw) * body[0] + math.cos(cyaw) * body[1]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([pose[0] + c * rx - s * ry, pose[1] + s * rx + c * ry])

    def compute(self, pose: np.ndarray, velocity: np.ndarray, target: BoundingBox | None,
                depth_image: np.ndarray | None, obstacles: ObstacleInput = None, new_measurement: bool = True,
                seen_from: np.ndarray | None = None) -> ControlResult:
        """One control step. ``new_measurement=False`` says ``target`` is the detection already
        used in an earlier step (the detector runs slower than the control loop): it is not
        measured again, as projecting an old box with the robot's newer pose would move the
        target with the robot's own turning; the target's predicted position is followed.
        ``seen_from``: the robot's pose when the camera took the picture (``PoseHistory`` at
        the detection's stamp); the box is projected from there (default: ``pose``)."""
        cfg = self.config
        pose, velocity = robot_state(pose, velocity)
        dt = cfg.control_time_step
        self._since_measurement += dt
        if target is not None and depth_image is not None and not new_measurement and self.tracker.position is not None:
            predicted = self.tracker.predict(dt)
            assert predicted is not None  # the tracker has a position, so it predicts one
            return self._follow(pose, velocity, predicted, obstacles, ControlStatus.RUNNING)
        measured = None
        if target is not None and depth_image is not None:
            measured = self._target_world(target, depth_image, pose if seen_from is None else np.asarray(seen_from, dtype=np.float64))
        if measured is None:
            predicted = self.tracker.predict(dt)
            cmd, status = self.search.step()
            if status is ControlStatus.WAITING and predicted is not None:
                # Keep following the prediction while waiting for detections to come back.
                return self._follow(pose, velocity, predicted, obstacles, ControlStatus.WAITING)
            cmds = ramp_commands(self.robot, velocity, cmd[None], dt, cfg.control_horizon)[0]
            return ControlResult(cmds, integrate_sequence(pose, cmds, dt)[0], status)
        predicted = self.tracker.predict(dt)
        if predicted is not None:
            verdict = self._gate(measured, predicted)
            if verdict == "outside":
                self._candidate = None
                self._gate_misses += 1
                if self._gate_misses < cfg.target_gate_misses:
                    return self._follow(pose, velocity, predicted, obstacles, ControlStatus.RUNNING)
                self.tracker = _AlphaBeta()  # it keeps disagreeing: the target is where it is measured
            elif verdict == "reachable":
                confirmed = self._candidate is not None and float(np.hypot(*(measured - self._candidate))) <= cfg.target_gate
                if not confirmed:
                    self._candidate = measured
                    return self._follow(pose, velocity, predicted, obstacles, ControlStatus.RUNNING)
                self.tracker = _AlphaBeta()  # confirmed: the target is there, not partway from the old estimate
        self._candidate = None
        self._gate_misses = 0
        position = self.tracker.update(measured, self._since_measurement)  # velocity over the time between measurements
        self._since_measurement = 0.0
        local = measured - pose[:2]
        self.search.seen(math.sin(wrap_angle(math.atan2(local[1], local[0]) - pose[2])))
        if self.distance is None:
            self.distance = float(np.hypot(*local))
        return self._follow(pose, velocity, position, obstacles, ControlStatus.RUNNING)

    def _gate(self, measured: np.ndarray, predicted: np.ndarray) -> str:
        """``"near"`` (within ``target_gate`` of the prediction), ``"reachable"`` (the target could
        have walked there since its last measurement) or ``"outside"``."""
        cfg = self.config
        off = float(np.hypot(*(measured - predicted)))
        if off <= cfg.target_gate:
            return "near"
        return "reachable" if off <= cfg.target_gate + cfg.target_max_speed * self._since_measurement else "outside"

    def goal_for(self, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Where to stand: ``distance`` from the target, on the robot's side, facing it."""
        assert self.distance is not None
        sight = math.atan2(target[1] - pose[1], target[0] - pose[0]) + self.config.target_orientation
        return np.array([target[0] - self.distance * math.cos(sight), target[1] - self.distance * math.sin(sight), sight])

    def _follow(self, pose: np.ndarray, velocity: np.ndarray, target: np.ndarray, obstacles: ObstacleInput,
                status: ControlStatus) -> ControlResult:
        cfg = self.config
        robot = self.robot
        dt = cfg.control_time_step
        lead = target + self.tracker.velocity * dt * cfg.prediction_horizon
        goal = self.goal_for(pose, lead)
        samples = dwa_samples(robot, velocity, dt, cfg.max_linear_samples, cfg.max_angular_samples)
        trajs = rollout(pose, samples, dt, cfg.prediction_horizon)
        pts = obstacle_points(obstacles, self.sensor_pose)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = np.stack([pose[0] + c * pts[:, 0] - s * pts[:, 1], pose[1] + s * pts[:, 0] + c * pts[:, 1]], -1)
        # The target itself shows up in the scan: it is the thing we approach, not an obstacle.
        if world.shape[0]:
            world = world[np.hypot(world[:, 0] - target[0], world[:, 1] - target[1]) > 0.5]
        world = voxel_downsample(world, 0.5 * cfg.octree_resolution)
        reach = float(np.abs(samples[:, 0]).max()) * dt * cfg.prediction_horizon + robot.radius + 0.5
        near = nearby_obstacles(world, pose[:2], reach)
        clear = pose_clearance(robot, trajs[:, 1:], near).min(axis=1) if near.shape[0] else np.full(len(samples), np.inf)
        ok = clear > cfg.safety_margin
        if not np.any(ok):
            cmds = ramp_commands(robot, velocity, np.zeros((1, 3)), dt, cfg.control_horizon)[0]
            return ControlResult(cmds, integrate_sequence(pose, cmds, dt)[0], ControlStatus.BLOCKED)
        idx = np.nonzero(ok)[0]
        lim = (robot.ctrl_vx_limits, robot.ctrl_vy_limits, robot.ctrl_omega_limits)
        # If the straight way to the goal is blocked, a detour reference leads around.
        weights, reference = cfg.costs_weights, None
        length = float(np.hypot(goal[0] - pose[0], goal[1] - pose[1]))
        if near.shape[0] and length > 0.1:
            n = int(np.ceil(length / 0.05)) + 1
            line = np.linspace(pose[:2], goal[:2], n)
            heading = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
            ref, self._detour_side = detour_reference(
                line, np.full(n, heading), np.linspace(0.0, length, n), n, near, robot.radius,
                cfg.safety_margin, self._detour_side)
            if ref.shape[0] != n or not np.allclose(ref, line):
                reference = ref
                weights = attrs.evolve(weights, reference_path_distance_weight=max(weights.reference_path_distance_weight, 3.0))
        costs = evaluate_costs(
            weights, trajs[idx], np.broadcast_to(samples[idx][:, None], (idx.size, cfg.prediction_horizon, 3)),
            reference_path=reference, goal=goal[:2], obstacle_min_distance=clear[idx] + robot.radius, robot_radius=robot.radius,
            dt=dt, acc_limits=np.array([axis.max_acc for axis in lim]), initial_velocity=velocity)
        end = trajs[idx, -1]
        facing = np.abs(wrap_angle(np.arctan2(lead[1] - end[:, 1], lead[0] - end[:, 0]) - end[:, 2]))
        # Facing the target matters once there; on the way (e.g. around an obstacle) it must
        # not outweigh getting there, so it fades out beyond 1 m from the goal.
        to_goal = np.hypot(end[:, 0] - goal[0], end[:, 1] - goal[1])
        total = costs.total + facing * np.clip(1.0 - to_goal, 0.0, 1.0)
        best = int(np.argmin(total))
        command = samples[idx[best]]
        return ControlResult(np.repeat(command[None], cfg.control_horizon, 0), trajs[idx[best]], status,
                             {"target": target.copy(), "goal": goal, "distance": self.distance})
