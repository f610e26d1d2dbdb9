"""Time-indexed collision checks of sampled arcs against moving obstacles.

A tracker (``mapping/tracking.py``) gives each moving obstacle a centre, a constant velocity
and a radius. The arc planner (``arcs.py``) asks :meth:`PredictedMovers.clearances` for the
smallest gap between the robot's footprint at each arc sample, at that sample's *time*, and
every obstacle *predicted to that time*. The check goes on past the arc's horizon with the
robot standing at the arc's end for ``hold`` s: an arc is only safe if the robot can stop
after it and not be run into, so the planner never parks in a mover's way. The predicted
positions grow a margin with time (``margin_rate``: velocity uncertainty).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import attrs
import numpy as np

from emos.config import validators as V

if TYPE_CHECKING:
    from ..mapping.tracking import TrackerConfig
    from .arcs import ArcPlanner

__all__ = ["MoverConfig", "PredictedMovers", "PredictionConfig", "near_movers"]


@attrs.define(frozen=True)
class PredictionConfig:
    hold: float = attrs.field(default=1.0, validator=V.finite_non_negative)  # s standing at the arc's end, checked too
    hold_step: float = attrs.field(default=0.1, validator=V.finite_non_negative)  # s between the hold's samples
    margin: float = attrs.field(default=0.06, validator=V.finite_non_negative)  # m kept from a predicted mover
    margin_rate: float = attrs.field(default=0.1, validator=V.finite_non_negative)  # m per s of prediction
    safe_clearance: float = attrs.field(default=0.5, validator=V.finite_non_negative)  # closer to a mover costs extra
    weight: float = attrs.field(default=2.0, validator=V.finite_non_negative)  # cost per m inside safe_clearance


def _tracker_config(value: object) -> TrackerConfig:
    from ..mapping.tracking import TrackerConfig

    if isinstance(value, TrackerConfig):
        return value
    if isinstance(value, dict):
        return TrackerConfig(**value)
    raise TypeError(f"MoverConfig.tracker: expected a TrackerConfig or a dict, got {type(value).__name__}")


def _prediction_config(value: object) -> PredictionConfig:
    if isinstance(value, PredictionConfig):
        return value
    if isinstance(value, dict):
        return PredictionConfig(**value)
    raise TypeError(f"MoverConfig.prediction: expected a PredictionConfig or a dict, got {type(value).__name__}")


def _default_tracker() -> TrackerConfig:
    from ..mapping.tracking import TrackerConfig

    return TrackerConfig()


@attrs.define(frozen=True)
class MoverConfig:
    """Moving-obstacle handling for an arc planner: how scans are tracked (``mapping.tracking``)
    and how the tracks are predicted and checked (``PredictionConfig``). ``wait_radius`` (m):
    with a moving track this near, slow or no progress is waiting for it, not being stuck.
    ``footprint_pad`` (m): obstacle points within a moving track's circle plus this are the
    mover's own (a grid or memory that holds them is not asked about them as static)."""

    tracker: TrackerConfig = attrs.field(factory=_default_tracker, converter=_tracker_config)
    prediction: PredictionConfig = attrs.field(factory=PredictionConfig, converter=_prediction_config)
    wait_radius: float = attrs.field(default=3.0, validator=V.number(ge=0, finite=True, what="a finite number of metres"))
    footprint_pad: float = attrs.field(default=0.15, validator=V.number(ge=0, finite=True, what="a finite number of metres"))


def near_movers(xy: np.ndarray, centres: np.ndarray, radii: np.ndarray, pad: float) -> np.ndarray:
    """Per point (N, 2): within ``pad`` of a mover's circle (``centres`` (M, 2), ``radii`` (M,))."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(centres) == 0 or len(xy) == 0:
        return np.zeros(len(xy), dtype=bool)
    d = np.hypot(xy[:, None, 0] - centres[None, :, 0], xy[:, None, 1] - centres[None, :, 1])
    return np.any(d <= np.asarray(radii)[None, :] + pad, axis=1)


@attrs.define(frozen=True, eq=False)
class PredictedMovers:
    """Moving obstacles as circles at ``stamp``: ``centres`` (M, 2), ``velocities`` (M, 2) m/s,
    ``radii`` (M,) m, all in the planner's (world) frame."""

    centres: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1, 2))
    velocities: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1, 2))
    radii: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1))
    config: PredictionConfig = attrs.field(factory=PredictionConfig)

    def __attrs_post_init__(self) -> None:
        if not (len(self.centres) == len(self.velocities) == len(self.radii)):
            raise ValueError(f"PredictedMovers: centres, velocities and radii must have one row per obstacle, got "
                             f"{len(self.centres)}, {len(self.velocities)}, {len(self.radii)}")

    def __len__(self) -> int:
        return len(self.centres)

    def clearances(self, planner: ArcPlanner, pose: np.ndarray, groups: list) -> np.ndarray:
        """Per arc (the planner's order): smallest footprint-to-mover gap over the arc and the
        hold after it, less the time-growing margin (m; <= 0 means predicted contact)."""
        cfg = self.config
        spec = planner.spec
        hx, hy, off = spec.length / 2, spec.width / 2, spec.center_offset
        x0, y0, th0 = (float(v) for v in pose)
        c0, s0 = math.cos(th0), math.sin(th0)
        # Movers in the start pose's frame.
        rel = self.centres - (x0, y0)
        mx = c0 * rel[:, 0] + s0 * rel[:, 1]
        my = -s0 * rel[:, 0] + c0 * rel[:, 1]
        vx = c0 * self.velocities[:, 0] + s0 * self.velocities[:, 1]
        vy = -s0 * self.velocities[:, 0] + c0 * self.velocities[:, 1]
        n_hold = int(round(cfg.hold / cfg.hold_step)) if cfg.hold > 0 and cfg.hold_step > 0 else 0
        out = []
        for (_v, _turns, dx, dy, ct, st, _wt, _reach), t in zip(groups, planner._times):
            if n_hold:
                horizon = float(t[-1])
                t = np.concatenate([t, horizon + cfg.hold_step * np.arange(1, n_hold + 1)])
                pad = lambda a: np.concatenate([a, np.repeat(a[:, -1:], n_hold, axis=1)], axis=1)  # noqa: E731
                dx, dy, ct, st = pad(dx), pad(dy), pad(ct), pad(st)
            # Mover positions at each sample time (samples, M), relative to each arc pose.
            px = mx[None, :] + vx[None, :] * t[:, None]
            py = my[None, :] + vy[None, :] * t[:, None]
            qx = px[None] - dx[..., None]
            qy = py[None] - dy[..., None]
            lx = ct[..., None] * qx + st[..., None] * qy - off
            ly = -st[..., None] * qx + ct[..., None] * qy
            # Box-to-centre gap (Chebyshev-like: never more than the true distance), less radius
            # and the margin grown over the prediction time.
            gap = np.maximum(np.abs(lx) - hx, np.abs(ly) - hy) - self.radii[None, None, :]
            gap = gap - (cfg.margin + cfg.margin_rate * t)[None, :, None]
            out.append(gap.min(axis=(1, 2)).astype(float))
        return np.concatenate(out)
