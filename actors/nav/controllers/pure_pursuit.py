"""Pure Pursuit path tracking with a simple-search collision avoidance layer.

Each step: find the lookahead point at ``L = max(lookahead_gain_forward * |v|,
min_lookahead_distance)`` ahead along the path, steer on the arc through it, predict the
motion over ``prediction_horizon`` steps and, if that prediction hits an obstacle, try angular
velocity offsets of ``path_search_step`` (alternating sides, smallest first, up to
``max_search_candidates`` per side) and keep the first collision-free one.
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

__all__ = ["PurePursuitConfig", "PurePursuit"]


@attrs.define
class PurePursuitConfig(FollowerConfig):
    """Spec parameters plus ``min_lookahead_distance`` (m), the lookahead at standstill."""

    lookahead_gain_forward: float = field(0.8, 0.0, 1e2)
    prediction_horizon: int = field(10, 1, 1000, int)
    path_search_step: float = field(0.2, 1e-3, 1e2)
    max_search_candidates: int = field(10, 1, 1000, int)
    min_lookahead_distance: float = field(0.3, 1e-3, 1e2)


class PurePursuit(PathFollower):
    config: PurePursuitConfig

    def __init__(self, robot: RobotConfig, config: PurePursuitConfig | None = None) -> None:
        super().__init__(robot, config or PurePursuitConfig())
        # Detour memory: the side (+1/-1) of the last detour and how many steps it stays
        # preferred. Without it a robot beside an obstacle alternates between "rotate back
        # towards the path" and "turn away", and never passes.
        self._side = 0.0
        self._commit = 0
        self._spins_from = 0  # the first turn-in-place row of the last candidates()

    def nominal_command(self, pose: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, bool]:
        """Pure pursuit command towards the lookahead point; also whether it rotates in place."""
        assert self.progress is not None and self.path is not None
        cfg = self.config
        speed = float(np.hypot(velocity[0], velocity[1]))
        lookahead = max(cfg.lookahead_gain_forward * speed, cfg.min_lookahead_distance)
        idx = self.progress.point_ahead(lookahead)
        target = self.path.points[idx]
        local = to_robot_frame(pose, target)
        xt, yt = float(local[0]), float(local[1])
        dist2 = max(xt * xt + yt * yt, 1e-9)
        v = self.desired_speed()
        robot = self.robot
        if robot.model_type is RobotType.OMNI:
            heading = self.heading_error(pose[2], float(self.path.yaw[self.progress.index]))
            if self._commit == 0 and self.needs_rotation(heading):
                return self.rotate_command(heading), True
            scale = v / math.sqrt(dist2)
            w = -2.0 * heading / max(cfg.control_time_step * cfg.prediction_horizon, 1e-3)
            return np.array([xt * scale, yt * scale, w]), False
        alpha = math.atan2(yt, xt)
        if self._commit == 0 and self.needs_rotation(-alpha):
            return self.rotate_command(-alpha), True
        curvature = 2.0 * yt / dist2
        if robot.model_type is RobotType.ACKERMANN:
            curvature = float(np.clip(curvature, -robot.max_curvature, robot.max_curvature))
        w_max = robot.ctrl_omega_limits.max_vel
        if abs(v * curvature) > w_max:  # keep the arc, slow down to the angular limit
            v = w_max / abs(curvature)
        return np.array([v, 0.0, v * curvature]), False

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None, **inputs: Any) -> ControlResult:
        """One control step from the current world ``pose`` and body ``velocity``."""
        self.no_other_inputs(inputs)
        pose, velocity = robot_state(pose, velocity)
        if self.progress is None:
            return self._no_path(pose)
        self.progress.update(pose)
        if self.goal_reached(pose):
            return self._done(pose)
        cfg = self.config
        nominal, rotating = self.nominal_command(pose, velocity)
        obs = self.world_obstacles(pose, obstacles)
        steps = cfg.prediction_horizon
        targets = self.candidates(nominal)
        # Every candidate is checked over the same *distance*: a slower candidate gets a
        # proportionally longer horizon. Otherwise "the same, but at half speed" looks free
        # only because it sees less far, and the robot creeps into the obstacle.
        reach = np.maximum(np.hypot(targets[:, 0], targets[:, 1]), 1e-9)
        full = max(float(np.hypot(nominal[0], nominal[1])), float(reach.max()))
        horizon = np.clip(np.ceil(steps * full / reach), steps, 2 * steps).astype(int)
        horizon[reach < 1e-6] = steps  # turning in place: its own horizon
        mask = np.arange(2 * steps)[None, :] < horizon[:, None]
        valid = np.concatenate([np.ones((len(targets), 1), dtype=bool), mask], axis=1)
        here = self.clearances(np.repeat(pose[None, None], 2, axis=1), obs)[0]
        # Keep the safety margin; if already inside it, at least do not get closer.
        needed = min(cfg.safety_margin, here - 1e-3)
        # The nominal command is the first choice: when it is clear, the detours (which could
        # only come after it) need no checking. Same choice, a fraction of the work.
        cmds, poses = self.plan(pose, velocity, targets[:1], 2 * steps)
        clear = self.clearances(poses, obs, valid=valid[:1])
        if not clear[0] > needed:
            cmds, poses = self.plan(pose, velocity, targets, 2 * steps)
            clear = self.clearances(poses, obs, valid=valid)
        cmds = cmds[:, :steps]
        poses = poses[:, : steps + 1]
        ok = np.nonzero(clear > needed)[0]
        if ok.size == 0:
            return self._back_off(pose, velocity, obs, steps, here, float(clear.max()))
        best = int(ok[0])
        chosen = targets[best] - targets[0]
        offset = chosen[1] if self.robot.model_type is RobotType.OMNI else chosen[2]
        if best >= self._spins_from:  # a turn in place: its side is its own turn, not its offset from the arc
            offset = targets[best][2]
        if best > 0 and offset != 0.0:
            self._side, self._commit = math.copysign(1.0, offset), steps
        else:
            self._commit = max(0, self._commit - 1)
        status = ControlStatus.ROTATING if rotating and best == 0 else (
            ControlStatus.RUNNING if best == 0 else ControlStatus.AVOIDING)
        return ControlResult(cmds[best], poses[best], status,
                             {"clearance": float(clear[best]), "tracked_index": self.progress.index})

    def _back_off(self, pose: np.ndarray, velocity: np.ndarray, obs: np.ndarray, steps: int,
                  here: float, best_forward: float) -> ControlResult:
        """Nothing ahead is free: reverse slowly (steering either way) if that gains clearance,
        otherwise brake. A car in particular cannot turn away without moving, so without this
        it would stay stuck nose-to-obstacle."""
        cfg = self.config
        k = np.arange(0, cfg.max_search_candidates + 1) * cfg.path_search_step
        back = np.zeros((2 * k.size, 3))
        back[:, 0] = -0.3 * self.robot.ctrl_vx_limits.max_vel
        back[:, 2] = np.concatenate([k, -k])
        cmds, poses = self.plan(pose, velocity, back, steps)
        clear = self.clearances(poses, obs)
        best = int(np.argmax(clear))
        if clear[best] > max(here, 0.0) + 1e-3 and clear[best] > 0.0:
            self._commit = steps
            self._side = -math.copysign(1.0, back[best, 2]) if back[best, 2] != 0 else self._side
            return ControlResult(cmds[best], poses[best], ControlStatus.AVOIDING,
                                 {"clearance": float(clear[best]), "reversing": True})
        brake, plan = self.plan(pose, velocity, np.zeros((1, 3)), steps)
        return ControlResult(brake[0], plan[0], ControlStatus.BLOCKED, {"clearance": best_forward})

    def candidates(self, nominal: np.ndarray) -> np.ndarray:
        """Nominal command first, then detours in order of growing offset.

        The offset (``path_search_step`` per candidate, alternating sides) applies to the
        angular velocity, or to the lateral velocity of an omni robot. Each offset is tried at
        full then half speed; differential robots finally try turning in place.
        """
        cfg = self.config
        robot = self.robot
        k = np.arange(1, cfg.max_search_candidates + 1) * cfg.path_search_step
        side = self._side if self._commit > 0 else 1.0
        deltas = np.concatenate([[0.0], side * k, -side * k] if self._commit > 0 else
                                [[0.0], np.stack([k, -k], axis=1).reshape(-1)])
        axis = 1 if robot.model_type is RobotType.OMNI else 2
        full = np.repeat(nominal[None], deltas.size, axis=0)
        if robot.model_type is RobotType.ACKERMANN:
            # A car changes its heading only while moving: keep detours moving.
            full[1:, 0] = max(nominal[0], 0.5 * robot.ctrl_vx_limits.max_vel)
        full[:, axis] += deltas
        half = full.copy()
        half[:, :2] *= 0.5
        out = np.stack([full, half], axis=1).reshape(-1, 3)
        self._spins_from = len(out)
        if robot.model_type is RobotType.DIFFERENTIAL_DRIVE:
            # Turns in place, the arc's own way first (or the committed side's): a robot whose
            # arc is blocked turns on towards its target. Trying +w first whatever the arc
            # wanted, and then taking the side from the turn's offset to the arc (a slower turn
            # the same way reads as the other side), a robot in a doorway whose arc to the path
            # was blocked turned back and forth in place for good (`emos bench costmap --drive`).
            way = self._side if self._commit > 0 else (math.copysign(1.0, nominal[2]) if nominal[2] != 0.0 else 1.0)
            spin = np.zeros((2 * k.size, 3))
            spin[:, 2] = np.stack([way * k, -way * k], axis=1).reshape(-1)
            out = np.vstack([out, spin])
        return out
