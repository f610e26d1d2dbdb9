"""Local planner: sample constant-velocity arcs, reject those whose footprint would touch a
known obstacle point, score the rest by cost-to-go (a dynamic-window search).

All candidates are checked at once with numpy: (arcs, time samples, points) arrays.
"""
from __future__ import annotations

import math
from typing import Callable

import attrs
import numpy as np

from ..robots import RobotSpec


@attrs.define
class ArcConfig:
    horizon: float = 1.0  # s of constant-velocity motion checked for collision
    step: float = 0.06  # m between collision samples along the fastest arc (< obstacle size)
    speeds: int = 7  # forward speeds from 0 to max
    turns: int = 17  # angular velocities from -max to max
    max_speed: float = 2.0
    max_turn: float = 3.0
    margin: float = 0.03  # m added around the footprint for the hard check
    safe_clearance: float = 0.12  # m; closer than this (+ speed term) costs extra
    clearance_weight: float = 6.0
    lookahead: float = 0.4  # m ahead of the arc end, scored too, to end aligned with the path


class ArcPlanner:
    def __init__(self, spec: RobotSpec, config: ArcConfig | None = None) -> None:
        self.spec = spec
        self.cfg = cfg = config or ArcConfig()
        vmax = min(cfg.max_speed, spec.max_vx)
        wmax = min(cfg.max_turn, spec.max_omega)
        v, w = np.meshgrid(np.linspace(0.0, vmax, cfg.speeds), np.linspace(-wmax, wmax, cfg.turns), indexing="ij")
        self.v, self.w = v.ravel(), w.ravel()
        n_samples = max(4, int(math.ceil(vmax * cfg.horizon / cfg.step)))
        # Rotations sweep the footprint corners too: sample them finely enough as well.
        n_samples = max(n_samples, int(math.ceil(wmax * cfg.horizon * spec.circumscribed_radius / cfg.step)))
        t = cfg.horizon * np.arange(1, n_samples + 1) / n_samples
        self.t = t
        # Arc poses relative to the start pose: (arcs, samples).
        wt = self.w[:, None] * t[None, :]
        straight = np.abs(self.w) < 1e-6
        safe_w = np.where(straight, 1.0, self.w)[:, None]
        self.dx = np.where(straight[:, None], self.v[:, None] * t, self.v[:, None] * np.sin(wt) / safe_w)
        self.dy = np.where(straight[:, None], 0.0, self.v[:, None] * (1 - np.cos(wt)) / safe_w)
        self.dth = wt

    def choose(self, pose: np.ndarray, points: np.ndarray,
               cost_to_go: Callable[[np.ndarray], np.ndarray]) -> tuple[float, float] | None:
        """Best (v, omega) from ``pose`` among arcs clear of world ``points``; None if none is."""
        cfg, spec = self.cfg, self.spec
        x0, y0, th0 = pose
        c0, s0 = math.cos(th0), math.sin(th0)
        hx, hy, off = spec.length / 2, spec.width / 2, spec.center_offset
        if len(points):
            rel = points - (x0, y0)
            # Obstacle points in the start frame, then in each sampled pose's frame.
            px = (c0 * rel[:, 0] + s0 * rel[:, 1]).astype(np.float32)
            py = (-s0 * rel[:, 0] + c0 * rel[:, 1]).astype(np.float32)
            ct, st = np.cos(self.dth).astype(np.float32)[..., None], np.sin(self.dth).astype(np.float32)[..., None]
            qx = px - self.dx.astype(np.float32)[..., None]
            qy = py - self.dy.astype(np.float32)[..., None]
            lx = ct * qx + st * qy - off
            ly = -st * qx + ct * qy
            gap = np.maximum(np.abs(lx) - hx, np.abs(ly) - hy)  # < 0 inside the footprint
            clearance = gap.min(axis=(1, 2))
        else:
            clearance = np.full(len(self.v), np.inf)
        ok = clearance > cfg.margin
        if not ok.any():
            return None
        end_th = th0 + self.dth[:, -1]
        ex = x0 + c0 * self.dx[:, -1] - s0 * self.dy[:, -1]
        ey = y0 + s0 * self.dx[:, -1] + c0 * self.dy[:, -1]
        ends = np.c_[ex, ey]
        ahead = ends + cfg.lookahead * np.c_[np.cos(end_th), np.sin(end_th)]
        score = cost_to_go(ends) + cost_to_go(ahead)
        wanted = cfg.safe_clearance + 0.1 * self.v
        score = score + cfg.clearance_weight * np.maximum(0.0, wanted - clearance)
        score = np.where(ok, score, np.inf)
        best = int(np.argmin(score))
        if not np.isfinite(score[best]):
            # Every clear arc ends somewhere the global field calls unreachable: turn in place
            # on the clear rotation that keeps the most clearance.
            rotations = ok & (self.v == 0)
            if not rotations.any():
                return None
            best = int(np.argmax(np.where(rotations, clearance, -np.inf)))
        return float(self.v[best]), float(self.w[best])
