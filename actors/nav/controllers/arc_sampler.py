"""The arc sampler as a path follower (``ControllersID.ARC_SAMPLER``).

Every step samples constant (v, omega) arcs within the robot's limits (:class:`ArcPlanner`),
drops those whose box footprint would come within ``margin`` of an obstacle point, and scores
the rest by a cost-to-go and a clearance penalty. The cost-to-go is a :class:`CostField`
(Dijkstra around the obstacles seen) over a window around the robot, towards the point of the
path ``path_window`` metres ahead: arcs that lead round an obstacle score better than standing
in front of it, which a plain distance-to-path cost would not see. It is the local planner of
the mapless BARN navigator, usable by the Controller like any other algorithm.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import attrs
import numpy as np

from ..kinematics import integrate_sequence
from ..planning.costfield import footprint_field
from ..robot import RobotConfig
from .arcs import ArcConfig, ArcPlanner
from .base import ControlResult, ControlStatus, FollowerConfig
from .follower import PathFollower
from .movers import MoverConfig, PredictedMovers, near_movers
from .response import ResponseConfig, YawGainEstimator
from .sensors import LaserScan2D, ObstacleInput, obstacle_points

__all__ = ["ArcSampler", "ArcSamplerConfig"]


def _arc_config(value: object) -> ArcConfig:
    if isinstance(value, ArcConfig):
        return value
    if isinstance(value, dict):
        return ArcConfig(**value)
    raise TypeError(f"ArcSamplerConfig.arcs: expected an ArcConfig, got {type(value).__name__}")


def _movers(value: object) -> MoverConfig | None:
    if value is None or isinstance(value, MoverConfig):
        return value
    if isinstance(value, dict):
        return MoverConfig(**value)
    raise TypeError(f"ArcSamplerConfig.movers: expected a MoverConfig, a dict or None, got {type(value).__name__}")


def _response(value: object) -> ResponseConfig | None:
    if value is None or isinstance(value, ResponseConfig):
        return value
    if isinstance(value, dict):
        return ResponseConfig(**value)
    raise TypeError(f"ArcSamplerConfig.response: expected a ResponseConfig, a dict or None, got {type(value).__name__}")


@attrs.define
class ArcSamplerConfig(FollowerConfig):
    """``arcs``: the sampling (horizon, speeds, turns, margins, clearance weights).
    ``path_window`` (m): how far ahead on the path the cost-to-go leads. ``final_approach``
    (m): closer than this to the end of the path the robot steers straight at it (sampled
    arcs with a look-ahead cannot stop on a point)."""

    arcs: ArcConfig = attrs.field(factory=lambda: ArcConfig(max_speed=2.0, reverse_speed=0.0), converter=_arc_config)
    path_window: float = attrs.field(default=2.5, converter=float)
    response: ResponseConfig | None = attrs.field(default=None, converter=_response)
    """A response model (``response.py``): check and score the arcs the base achieves from
    its measured velocity, with its yaw gain estimated online, and a margin growing with
    speed (a skid-steer base that turns less than commanded). None: commanded arcs."""
    movers: MoverConfig | None = attrs.field(default=None, converter=_movers)
    """Moving obstacles (``movers.py``): track the scan's clusters between steps (a scan in
    beam order, one ``compute`` per control step), keep the moving ones out of the static
    check and check each arc against their predicted positions; standing still to let one
    pass is running, not blocked. With a grid or point obstacles (no beam order), give the
    scan to track as ``compute(..., scan=...)``: the obstacle points on a moving track's
    circle are then the mover's, not static. None: every point is static."""
    field_resolution: float = attrs.field(default=0.1, converter=float)
    final_approach: float = attrs.field(default=0.6, converter=float)


class ArcSampler(PathFollower):
    config: ArcSamplerConfig

    def __init__(self, robot: RobotConfig, config: ArcSamplerConfig | None = None) -> None:
        super().__init__(robot, config or ArcSamplerConfig())
        self.arcs = ArcPlanner(robot, self.config.arcs, response=self.config.response)
        self._gain = (YawGainEstimator(self.config.response, self.config.control_time_step)
                      if self.config.response is not None else None)
        self._last_turn = 0.0
        self._tracker = None
        self._clock = 0.0  # s of control steps: the tracker's time base
        self.scan_pose = (0.0, 0.0, 0.0)  # (x, y, yaw) on the robot of a ``scan`` given to compute
        self.waiting = False  # the last step had a moving track within ``movers.wait_radius``
        if self.config.movers is not None:
            from ..mapping.tracking import ScanTracker

            self._tracker = ScanTracker(self.config.movers.tracker)
        # The capability (PathFollower.tracks_movers): configured for moving obstacles, so
        # ``compute`` takes a ``scan``.
        self.tracks_movers = self._tracker is not None

    def _split_movers(self, pose: np.ndarray, points: np.ndarray,
                      scan: LaserScan2D | None) -> tuple[np.ndarray, PredictedMovers | None]:
        """(static points, predicted movers) after feeding this step's scan (or obstacle points,
        when they are the scan) to the tracker."""
        if self._tracker is None:
            return points, None
        cfg = self.config.movers
        assert cfg is not None
        self._clock += self.config.control_time_step
        mount = self.scan_pose if scan is not None else self.sensor_pose
        c, s = math.cos(pose[2]), math.sin(pose[2])
        origin = (pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0] + c * mount[1])
        if scan is None:
            moving = self._tracker.update(self._clock, points, origin)
        else:
            local = obstacle_points(scan, mount)
            world = np.c_[pose[0] + c * local[:, 0] - s * local[:, 1], pose[1] + s * local[:, 0] + c * local[:, 1]]
            self._tracker.update(self._clock, world, origin, float(scan.angle_increment or 0.0))
        centres, velocities, radii = self._tracker.movers(self._clock)
        if scan is not None:
            # The grid marks where each mover is now: those cells are the mover, not static.
            moving = near_movers(points, centres, radii, cfg.footprint_pad)
        self.waiting = bool(len(centres)) and float(np.min(np.hypot(centres[:, 0] - pose[0], centres[:, 1] - pose[1]))) \
            <= cfg.wait_radius
        movers = PredictedMovers(centres, velocities, radii, cfg.prediction) if len(centres) else None
        return points[~moving], movers

    def _local_field(self, pose: np.ndarray, points: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Cost-to-go over a square window around the robot, to the path point ahead."""
        assert self.path is not None and self.progress is not None
        cfg, res = self.config, self.config.field_resolution
        half = cfg.path_window + 0.5
        origin = pose[:2] - half
        n = int(math.ceil(2 * half / res))
        carrot_i = int(self.path.index_at(self.path.s[self.progress.index] + cfg.path_window))
        carrot = self.path.points[carrot_i]
        left = float(self.path.length - self.path.s[carrot_i])
        occupied = np.zeros((n, n), dtype=bool)
        ij = np.floor((points - origin) / res).astype(int)
        inside = np.all((ij >= 0) & (ij < n), axis=1)
        occupied[ij[inside, 1], ij[inside, 0]] = True
        field = footprint_field((n, n), res, self.arcs.spec.width / 2)
        gc = np.clip(np.floor((carrot - origin) / res).astype(int), 0, n - 1)
        field.compute(occupied, (int(gc[1]), int(gc[0])))
        ctg = field.ctg_filled

        def cost_to_go(xy: np.ndarray) -> np.ndarray:
            cells = np.floor((xy - origin) / res).astype(int)
            ok = np.all((cells >= 0) & (cells < n), axis=1)
            c = np.clip(cells, 0, n - 1)
            out = np.where(ok, ctg[c[:, 1], c[:, 0]], np.hypot(*(xy - carrot).T) + 5.0)
            return np.where(np.isfinite(out), out, 1e3) + left

        return cost_to_go

    def compute(self, pose: np.ndarray, velocity: np.ndarray, obstacles: ObstacleInput = None,
                scan: LaserScan2D | None = None, **inputs: Any) -> ControlResult:
        """One control step. ``scan`` (with ``movers``, sensor frame, mounted at ``scan_pose``):
        the scan to track movers in when ``obstacles`` is not that scan (a local map)."""
        self.no_other_inputs(inputs)
        if scan is not None and not isinstance(scan, LaserScan2D):
            raise TypeError(f"ArcSampler.compute: scan must be a LaserScan2D or None, got {type(scan).__name__}")
        self.waiting = False
        pose = np.asarray(pose, dtype=np.float64).reshape(3)
        if self.path is None or self.progress is None:
            return self._no_path(pose)
        self.progress.update(pose)
        if self.goal_reached(pose):
            return self._done(pose)
        points = self.world_obstacles(pose, obstacles)
        dt = self.config.control_time_step
        if self.progress.remaining < self.config.final_approach:
            return self._final_approach(pose, dt)
        twist, gain = None, None
        if self._gain is not None:
            twist = np.asarray(velocity, dtype=float).reshape(3)
            gain = self._gain.update(self._last_turn, float(twist[0]), float(twist[2]))
        points, movers = self._split_movers(pose, points, scan)
        choice = self.arcs.choose(pose, points, self._local_field(pose, points), twist=twist, yaw_gain=gain,
                                  movers=movers)
        if choice == (0.0, 0.0) and movers is not None:
            # Standing still scores best while a mover crosses: waiting, not blocked.
            self._last_turn = 0.0
            return ControlResult.stop(pose, ControlStatus.RUNNING)
        if choice is None or choice == (0.0, 0.0):
            # No clear arc, or standing still scores best: no trajectory makes progress.
            self._last_turn = 0.0
            return ControlResult.stop(pose, ControlStatus.BLOCKED)
        v, w = choice
        self._last_turn = w
        speed_cap = self.desired_speed()  # brake towards the end of the path
        if v > speed_cap:
            w *= speed_cap / max(v, 1e-9)
            v = speed_cap
        cmd = np.array([[v, 0.0, w]])
        steps = max(1, int(math.ceil(self.config.arcs.horizon / dt)))
        plan = integrate_sequence(pose, np.repeat(cmd, steps, axis=0), dt)[0]
        return ControlResult(cmd, plan, ControlStatus.RUNNING)

    def _final_approach(self, pose: np.ndarray, dt: float) -> ControlResult:
        assert self.path is not None
        end = self.path.points[-1]
        error = self.heading_error(pose[2], math.atan2(end[1] - pose[1], end[0] - pose[0]))
        if self.needs_rotation(error):
            cmd = self.rotate_command(error)
        else:
            w_max = self.robot.ctrl_omega_limits.max_vel
            cmd = np.array([self.desired_speed() * max(0.0, math.cos(error)), 0.0, float(np.clip(-2.0 * error, -w_max, w_max))])
        plan = integrate_sequence(pose, cmd[None, None, :], dt)[0]
        return ControlResult(cmd[None, :], plan, ControlStatus.RUNNING)
