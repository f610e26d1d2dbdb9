"""The mapless navigator for worlds with moving obstacles (BARN's ``builtin-dynamic``).

``GridNavigator`` remembers every lidar hit forever and plans as if nothing moved: a crossing
obstacle leaves a wall of old positions across the corridor, and the arcs are checked against
where obstacles *were*. ``DynamicGridNavigator`` keeps its parts and changes three things,
using only the robot's scans and its own pose estimate (odometry corrected by scan matching):

- memory with evidence decay (``mapping.EvidenceGrid``): cells the lidar later sees through
  are released, so a mover's trail never blocks the corridor for long; walls stay;
- a tracker (``mapping.ScanTracker``): clusters associated between scans, a constant-velocity
  estimate per track; points of moving tracks stay out of the memory and out of scan matching;
- time-indexed arc checks (``controllers.movers``): each arc, and standing at its end for a
  while after it, is checked against the movers' predicted positions, so the robot slows or
  waits (the speed-only arcs are in the set) instead of driving or parking in a mover's way.
  Waiting for a mover nearby does not count as being stuck (no backing out, no blocks).
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from ..controllers.movers import MoverConfig, PredictedMovers, near_movers
from ..mapping import compose, correction_between
from ..mapping.evidence import EvidenceConfig, EvidenceGrid
from ..mapping.tracking import ScanTracker
from .interface import NavTask, Observation
from .mapless import GridNavigator

__all__ = ["DynamicConfig", "DynamicGridNavigator"]


@attrs.define(frozen=True)
class DynamicConfig:
    """``movers``: tracking, predicted arc checks and the wait radius (a mover this near:
    waiting, not stuck); ``evidence``: how the memory forgets; ``fresh_time`` (s): a cell seen
    free this recently counts as fresh space (motion evidence)."""

    movers: MoverConfig = attrs.field(factory=MoverConfig, validator=attrs.validators.instance_of(MoverConfig))
    evidence: EvidenceConfig = attrs.field(factory=EvidenceConfig, validator=attrs.validators.instance_of(EvidenceConfig))
    fresh_time: float = attrs.field(default=1.0, validator=V.finite_non_negative)


class DynamicGridNavigator(GridNavigator):
    """``GridNavigator`` with evidence decay, mover tracking and predicted arc checks."""

    name = "builtin-dynamic"
    grid: EvidenceGrid  # built by make_grid below

    def __init__(self, dynamic: DynamicConfig | None = None, **kwargs: Any) -> None:
        if kwargs.get("carve_range", 0.0):
            raise ValueError("DynamicGridNavigator forgets by evidence decay; carve_range must stay 0")
        super().__init__(**kwargs)
        self.dynamic = dynamic or DynamicConfig()

    def reset(self, task: NavTask) -> None:
        self.tracker = ScanTracker(self.dynamic.movers.tracker)
        super().reset(task)

    def make_grid(self, bounds: tuple[float, float, float, float]) -> EvidenceGrid:
        return EvidenceGrid(bounds, self.resolution, cap=self.dynamic.evidence.cap)

    # -- perception ---------------------------------------------------------------------

    def _beams(self, pose: np.ndarray, scan: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sensor origin (2,), unit directions (N, 2), ranges (N,)) in the map frame."""
        mx, my, myaw = self._task.scan_mount
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        origin = np.array([x + c * mx - s * my, y + s * mx + c * my])
        angles = yaw + myaw + scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
        return origin, np.c_[np.cos(angles), np.sin(angles)], np.asarray(scan.ranges, dtype=float)

    def _near_movers(self, xy: np.ndarray, stamp: float) -> np.ndarray:
        centres, _, radii = self.tracker.movers(stamp)
        return near_movers(xy, centres, radii, self.dynamic.movers.footprint_pad)

    def localized(self, obs: Observation) -> Observation:
        """Scan matching as the static navigator, on the returns that are not moving tracks'."""
        if self._matcher is None or obs.scan is None:
            return super().localized(obs)
        guess = compose(self._correction, obs.pose)
        origin, d, r = self._beams(guess, obs.scan)
        hit = np.isfinite(r)
        world = origin + r[hit, None] * d[hit]
        static = ~self._near_movers(world, obs.stamp)
        mx, my, myaw = self._task.scan_mount
        a = obs.scan.angle_min + obs.scan.angle_increment * np.flatnonzero(hit)
        rr = r[hit]
        local = np.c_[mx + rr * np.cos(a + myaw), my + rr * np.sin(a + myaw)][static]
        pose, best, at_guess = self._matcher.match(self.grid, guess, local)
        if best > at_guess + 0.01:
            self._correction = correction_between(pose, np.asarray(obs.pose, dtype=float))
            guess = pose
        return Observation(obs.stamp, guess, obs.twist, obs.scan)

    def _insert_scan(self, obs: Observation) -> None:
        """Track clusters, decay the memory along the beams, remember the static returns."""
        scan = obs.scan
        assert scan is not None  # update() inserts only observations that carry a scan
        origin, d, r = self._beams(np.asarray(obs.pose, dtype=float), scan)
        hit = np.isfinite(r)
        world = origin + r[hit, None] * d[hit]
        # Motion evidence: hits where beams passed within the last ``fresh_time`` s and no
        # older obstacle is remembered (asked before this scan marks its own free space).
        grid = self.grid
        fresh = grid.moved_into(world, obs.stamp, self.dynamic.fresh_time)
        moving = self.tracker.update(obs.stamp, world, origin, float(scan.angle_increment), fresh)
        free = self.dynamic.evidence.free_range
        length = np.where(hit, np.minimum(r, free) - 1.5 * grid.resolution, free)
        grid.observe_free((float(origin[0]), float(origin[1])), d, np.maximum(length, 0.0), obs.stamp)
        # Withhold from the memory only a moving track's hits in space the lidar recently saw
        # free: a static object wrongly tracked as moving still enters the memory.
        grid.insert(world[~(moving & fresh)], obs.stamp)

    # -- planning -----------------------------------------------------------------------

    def movers(self, obs: Observation) -> PredictedMovers | None:
        centres, velocities, radii = self.tracker.movers(obs.stamp)
        if len(centres) == 0:
            return None
        return PredictedMovers(centres, velocities, radii, self.dynamic.movers.prediction)

    def _stuck(self, obs: Observation) -> bool:
        """Standing aside for a mover is not being stuck: the progress clock restarts."""
        centres, _, _ = self.tracker.movers(obs.stamp)
        if len(centres) and np.min(np.hypot(centres[:, 0] - obs.pose[0], centres[:, 1] - obs.pose[1])) \
                <= self.dynamic.movers.wait_radius:
            self._progress.reset()
            return False
        return super()._stuck(obs)
