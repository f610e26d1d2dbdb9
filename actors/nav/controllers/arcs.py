"""Arc sampler (local planner): sample constant-velocity arcs, reject those whose footprint would touch a
known obstacle point, score the rest by cost-to-go (a dynamic-window search).

All candidates are checked at once with numpy: (arcs, time samples, points) arrays.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import attrs
import numpy as np

from emos.config import validators as V

from ..kinematics import integrate
from ..robot import RobotConfig, RobotGeometry

if TYPE_CHECKING:
    from .movers import PredictedMovers
    from .response import ResponseConfig


@attrs.define
class ArcConfig:
    horizon: float = attrs.field(default=1.0, validator=V.finite_positive)  # s of constant-velocity motion checked
    step: float = attrs.field(default=0.06, validator=V.finite_positive)  # m between collision samples (< obstacle size)
    speeds: int = attrs.field(default=7, validator=V.int_at_least(2))  # forward speeds from 0 to max
    turns: int = attrs.field(default=17, validator=V.int_at_least(2))  # angular velocities from -max to max
    max_speed: float = attrs.field(default=2.0, validator=V.finite_positive)
    max_turn: float = attrs.field(default=3.0, validator=V.finite_positive)
    margin: float = attrs.field(default=0.015, validator=V.finite_non_negative)  # m around the footprint, hard check
    safe_clearance: float = attrs.field(default=0.12, validator=V.finite_non_negative)  # closer (+ speed term) costs extra
    clearance_weight: float = attrs.field(default=6.0, validator=V.finite_non_negative)
    lookahead: float = attrs.field(default=0.4, validator=V.finite_non_negative)  # m past the arc end, scored too
    reverse_speed: float = attrs.field(default=0.3, validator=V.finite_non_negative)  # m/s of backing-up arcs (0: none)
    reverse_cost: float = 1.0  # extra cost of backing up, so it is only chosen to get unstuck


@attrs.define(frozen=True)
class BoxFootprint:
    """The footprint the arc checks use: a box (``length`` x ``width``) whose centre is
    ``center_offset`` ahead of the base frame; round robots use their bounding square."""

    length: float
    width: float
    center_offset: float = 0.0

    @classmethod
    def of(cls, robot: RobotConfig, center_offset: float = 0.0) -> BoxFootprint:
        if robot.geometry_type is RobotGeometry.Type.BOX:
            return cls(float(robot.geometry_params[0]), float(robot.geometry_params[1]), center_offset)
        return cls(2.0 * robot.radius, 2.0 * robot.radius, center_offset)

    @property
    def circumscribed_radius(self) -> float:
        return math.hypot(self.length / 2, self.width / 2)


class ArcPlanner:
    """Samples (v, omega) arcs within the robot's limits and picks the best clear one."""

    def __init__(self, robot: RobotConfig, config: ArcConfig | None = None, center_offset: float = 0.0,
                 response: ResponseConfig | None = None) -> None:
        self.robot = robot
        # None: arcs are the commanded ones. Set: checked and scored as the base achieves them
        # (see response.py), when choose() is given the measured twist and the yaw gain.
        self.response = response
        self.spec = spec = BoxFootprint.of(robot, center_offset)
        self.cfg = cfg = config or ArcConfig()
        vmax = min(cfg.max_speed, robot.ctrl_vx_limits.max_vel)
        wmax = min(cfg.max_turn, robot.ctrl_omega_limits.max_vel)
        speeds = np.linspace(0.0, vmax, cfg.speeds)
        if cfg.reverse_speed > 0:
            speeds = np.concatenate([[-min(cfg.reverse_speed, vmax)], speeds])
        turns = np.linspace(-wmax, wmax, cfg.turns)
        # One group of arcs per speed: slow arcs need fewer samples and see fewer points,
        # which keeps the (arcs, samples, points) arrays small.
        self.groups: list = []
        self._times: list[np.ndarray] = []
        for v in speeds:
            swept = abs(v) * cfg.horizon + np.abs(turns) * cfg.horizon * spec.circumscribed_radius
            n = max(2, int(math.ceil(swept.max() / cfg.step)))
            t = cfg.horizon * np.arange(1, n + 1) / n
            # Poses along each arc, relative to the start: the kinematics' closed-form arcs.
            commands = np.stack([np.full_like(turns, v), np.zeros_like(turns), turns], axis=-1)
            rel = integrate(np.zeros(3), commands[:, None, :], t[None, :])  # (turns, n, 3)
            dx, dy, wt = rel[..., 0], rel[..., 1], rel[..., 2]
            reach = abs(v) * cfg.horizon + spec.circumscribed_radius + abs(spec.center_offset) + cfg.margin + 0.05
            self.groups.append((v, turns, dx.astype(np.float32), dy.astype(np.float32),
                                np.cos(wt).astype(np.float32), np.sin(wt).astype(np.float32), wt, reach))
            self._times.append(t)
        self.v = np.repeat(speeds, len(turns))
        self.w = np.tile(turns, len(speeds))

    def achieved_groups(self, twist: np.ndarray, gain: float) -> list:
        """The arc groups as the base achieves them from ``twist`` (v, vy, omega) with yaw gain
        ``gain`` under the response model (same layout as ``self.groups``)."""
        from .response import achieved_arcs

        assert self.response is not None
        v0, w0 = float(twist[0]), float(twist[2])
        out = []
        for (v, turns, *_rest, reach), t in zip(self.groups, self._times):
            dx, dy, wt = achieved_arcs(v, turns, t, v0, w0, gain, self.response)
            out.append((v, turns, dx.astype(np.float32), dy.astype(np.float32), np.cos(wt).astype(np.float32),
                        np.sin(wt).astype(np.float32), wt, reach + abs(v0) * self.cfg.horizon))
        return out

    def clearances(self, pose: np.ndarray, points: np.ndarray, groups: list | None = None) -> np.ndarray:
        """Smallest footprint-to-point gap (m, Chebyshev-like, < 0 = overlap) along each arc."""
        spec = self.spec
        x0, y0, th0 = pose
        c0, s0 = math.cos(th0), math.sin(th0)
        hx, hy, off = spec.length / 2, spec.width / 2, spec.center_offset
        out = []
        rel = np.asarray(points, dtype=float).reshape(-1, 2) - (x0, y0)
        px_all = (c0 * rel[:, 0] + s0 * rel[:, 1]).astype(np.float32)
        py_all = (-s0 * rel[:, 0] + c0 * rel[:, 1]).astype(np.float32)
        d2 = px_all**2 + py_all**2
        for _v, turns, dx, dy, ct, st, _, reach in (self.groups if groups is None else groups):
            near = d2 <= reach * reach
            if not near.any():
                out.append(np.full(len(turns), np.inf))
                continue
            px, py = px_all[near], py_all[near]
            qx = px - dx[..., None]
            qy = py - dy[..., None]
            lx = ct[..., None] * qx + st[..., None] * qy - off
            ly = -st[..., None] * qx + ct[..., None] * qy
            gap = np.maximum(np.abs(lx) - hx, np.abs(ly) - hy)
            out.append(gap.min(axis=(1, 2)).astype(float))
        return np.concatenate(out)

    def _here_clearance(self, pose: np.ndarray, points: np.ndarray) -> float:
        if len(points) == 0:
            return math.inf
        x0, y0, th0 = pose
        c0, s0 = math.cos(th0), math.sin(th0)
        rel = np.asarray(points, dtype=float).reshape(-1, 2) - (x0, y0)
        lx = c0 * rel[:, 0] + s0 * rel[:, 1] - self.spec.center_offset
        ly = -s0 * rel[:, 0] + c0 * rel[:, 1]
        return float(np.min(np.maximum(np.abs(lx) - self.spec.length / 2, np.abs(ly) - self.spec.width / 2)))

    def choose(self, pose: np.ndarray, points: np.ndarray, cost_to_go: Callable[[np.ndarray], np.ndarray],
               reverse_cost: float | None = None, twist: np.ndarray | None = None,
               yaw_gain: float | None = None, movers: PredictedMovers | None = None) -> tuple[float, float] | None:
        """Best (v, omega) from ``pose`` among arcs clear of world ``points``; None if none is.
        ``reverse_cost`` overrides the configured cost of backing up (recovery makes it < 0).
        With a response model, ``twist`` (measured) and ``yaw_gain``: arcs as achieved, and a
        margin that grows with speed. ``movers``: moving obstacles, checked at each sample's
        time against their predicted positions (``movers.py``)."""
        cfg = self.cfg
        reverse_cost = cfg.reverse_cost if reverse_cost is None else reverse_cost
        groups = None
        margin = np.full(len(self.v), cfg.margin)
        if self.response is not None and twist is not None:
            gain = self.response.prior_gain if yaw_gain is None else yaw_gain
            groups = self.achieved_groups(np.asarray(twist, dtype=float), gain)
            margin = margin + self.response.speed_margin * np.abs(self.v)
        clearance = self.clearances(pose, points, groups)
        # Already closer than the margin (sensor noise, a tight squeeze): accept any arc that
        # does not get closer still, so the robot can always back or turn away.
        here = self._here_clearance(pose, points)
        ok = clearance > np.minimum(margin, here - 1e-3)
        if not ok.any():
            return None
        x0, y0, th0 = pose
        c0, s0 = math.cos(th0), math.sin(th0)
        ends = []
        for _v, _turns, dx, dy, _, _, wt, _ in (self.groups if groups is None else groups):
            ex = x0 + c0 * dx[:, -1] - s0 * dy[:, -1]
            ey = y0 + s0 * dx[:, -1] + c0 * dy[:, -1]
            ends.append(np.c_[ex, ey, th0 + wt[:, -1]])
        end = np.concatenate(ends)
        # Look ahead in the direction of travel (behind the robot for backing-up arcs).
        travel = np.where(self.v < 0, -1.0, 1.0)[:, None]
        ahead = end[:, :2] + travel * cfg.lookahead * np.c_[np.cos(end[:, 2]), np.sin(end[:, 2])]
        score = cost_to_go(end[:, :2]) + cost_to_go(ahead)
        wanted = cfg.safe_clearance + 0.1 * np.abs(self.v)
        score = score + cfg.clearance_weight * np.maximum(0.0, wanted - clearance)
        score = score + np.where(self.v < 0, reverse_cost, 0.0)
        if movers is not None and len(movers):
            mover_gap = movers.clearances(self, pose, self.groups if groups is None else groups)
            safe = ok & (mover_gap > 0)
            if safe.any():
                ok = safe
                mc = movers.config
                score = score + mc.weight * np.maximum(0.0, mc.safe_clearance - mover_gap)
            else:
                # No arc escapes the predicted movers: take the clear arc that stays farthest from them.
                score = -mover_gap
        score = np.where(ok, score, np.inf)
        best = int(np.argmin(score))
        if not np.isfinite(score[best]):
            return None
        return float(self.v[best]), float(self.w[best])
