"""Tracking moving obstacles between lidar scans, with what a real robot has: scans placed in
the odometry (or scan-matched) frame at the robot's own pose estimate. Never ground truth.

Each scan is cut into clusters where consecutive beam endpoints jump apart; clusters wider
than ``max_extent`` are structure (walls) and not tracked. Each small cluster gives a centre
estimate (its centroid pushed back along the view ray by the share of a round object's
radius the visible arc hides) and is associated with the nearest predicted track within a
gate (greedy nearest neighbour, closest pairs first). A track's velocity is the least-squares
slope of its centres over the last ``window`` seconds (constant velocity). A track is
*moving* once it has been seen ``min_observations`` times over at least ``min_span`` s and its
speed exceeds ``moving_speed``; it stops being moving only below half that (hysteresis). A
lost track coasts on its velocity for ``coast_time`` s (occlusion) before it is dropped.
"""
from __future__ import annotations

import math
from collections import deque

import attrs
import numpy as np

from emos.config import validators as V

__all__ = ["ScanTracker", "Track", "TrackerConfig", "segment"]


@attrs.define(frozen=True)
class TrackerConfig:
    cluster_gap: float = attrs.field(default=0.15, validator=V.finite_positive)  # m between neighbours of one cluster
    max_extent: float = attrs.field(default=1.0, validator=V.finite_positive)  # m; wider clusters are structure
    min_points: int = attrs.field(default=3, validator=attrs.validators.ge(1))
    gate: float = attrs.field(default=0.45, validator=V.finite_positive)  # m around a track's prediction
    window: float = attrs.field(default=1.0, validator=V.finite_positive)  # s of centres in the velocity fit
    min_observations: int = attrs.field(default=6, validator=attrs.validators.ge(2))
    min_span: float = attrs.field(default=0.5, validator=V.finite_positive)  # s the fit must cover
    moving_speed: float = attrs.field(default=0.15, validator=V.finite_positive)  # m/s
    max_speed: float = attrs.field(default=3.0, validator=V.finite_positive)  # faster is a wrong association
    coast_time: float = attrs.field(default=0.6, validator=V.finite_positive)  # s a lost track is predicted
    release_time: float = attrs.field(default=1.0, validator=V.finite_positive)  # s slow before moving is revoked
    max_range: float = attrs.field(default=12.0, validator=V.finite_positive)  # m; farther returns are not tracked
    max_residual: float = attrs.field(default=0.03, validator=V.finite_positive)  # m RMS of centres off the fitted line
    min_fresh: float = attrs.field(default=0.0, validator=attrs.validators.ge(0.0))  # share of hits in fresh space


@attrs.define(eq=False)
class Track:
    id: int
    history: deque  # (t, x, y) centres
    radius: float
    last_seen: float
    velocity: np.ndarray = attrs.field(factory=lambda: np.zeros(2))
    moving: bool = False
    points: np.ndarray = attrs.field(factory=lambda: np.zeros((0, 2)))  # last cluster (world frame)
    fresh: deque = attrs.field(factory=lambda: deque(maxlen=8))  # per scan: share of hits in space seen free
    residual: float = 0.0  # m RMS of the centres about the velocity fit
    slow_since: float | None = None  # stamp since when a moving track has been slow

    @property
    def position(self) -> np.ndarray:
        _, x, y = self.history[-1]
        return np.array([x, y])

    def predict(self, stamp: float) -> np.ndarray:
        return self.position + self.velocity * (stamp - self.last_seen)

    @property
    def observations(self) -> int:
        return len(self.history)


def segment(points: np.ndarray, origin: np.ndarray, gap: float, angle_increment: float = 0.0) -> list[np.ndarray]:
    """Index arrays of clusters of ``points`` (N, 2, in beam order): a new cluster starts where
    consecutive points are farther apart than ``gap`` plus the spacing of neighbouring beams
    at that range (so far objects are not cut into single points)."""
    n = len(points)
    if n == 0:
        return []
    rng = np.hypot(points[:, 0] - origin[0], points[:, 1] - origin[1])
    step = np.hypot(*np.diff(points, axis=0).T) if n > 1 else np.zeros(0)
    allowed = gap + 2.0 * angle_increment * np.maximum(rng[:-1], rng[1:])
    cuts = np.nonzero(step > allowed)[0] + 1
    return [idx for idx in np.split(np.arange(n), cuts)]


class ScanTracker:
    """``update(stamp, points, origin)`` once per scan; ``moving_tracks(stamp)`` for planning."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.cfg = config or TrackerConfig()
        self.tracks: list[Track] = []
        self._next_id = 0

    def _fit_velocity(self, track: Track) -> None:
        cfg = self.cfg
        h = np.asarray(track.history, dtype=float)
        h = h[h[:, 0] >= h[-1, 0] - cfg.window]
        if len(h) < 2 or h[-1, 0] - h[0, 0] <= 1e-6:
            return
        t = h[:, 0] - h[:, 0].mean()
        denom = float(np.sum(t * t))
        v = np.array([np.sum(t * (h[:, 1] - h[:, 1].mean())), np.sum(t * (h[:, 2] - h[:, 2].mean()))]) / denom
        speed = float(np.hypot(*v))
        if speed > cfg.max_speed:
            v = v * (cfg.max_speed / speed)
            speed = cfg.max_speed
        track.velocity = v
        fit = h[:, 1:] - h[:, 1:].mean(axis=0) - t[:, None] * v[None, :]
        track.residual = float(np.sqrt(np.mean(np.sum(fit * fit, axis=1))))
        mature = len(h) >= cfg.min_observations and h[-1, 0] - h[0, 0] >= cfg.min_span
        # Motion shows as hits where the lidar saw free space moments ago; a static object
        # seen from a new angle (its centroid shifting) does not do that, nor jump about.
        fresh = float(np.mean(track.fresh)) if track.fresh else 1.0
        stamp = float(h[-1, 0])
        if mature and speed > cfg.moving_speed and track.residual <= cfg.max_residual and fresh >= cfg.min_fresh:
            track.moving = True
        if not track.moving or speed >= 0.5 * cfg.moving_speed:
            track.slow_since = None
        elif track.slow_since is None:
            track.slow_since = stamp
        elif stamp - track.slow_since >= cfg.release_time:
            # Slow for a while, not just turning round at the end of its run: static now.
            track.moving = False
            track.slow_since = None

    def update(self, stamp: float, points: np.ndarray, origin: tuple[float, float] | np.ndarray,
               angle_increment: float = 0.0, fresh: np.ndarray | None = None) -> np.ndarray:
        """Feed one scan's hit points (N, 2, world frame, beam order) seen from ``origin``.
        ``fresh`` (optional, bool per point): the point lies where the lidar recently saw free
        space and nothing is remembered (``EvidenceGrid.seen_free_since``); a track becomes
        moving only if at least ``min_fresh`` of its hits are. Returns a bool per point: it
        belongs to a moving track (the caller keeps such points out of its static memory)."""
        cfg = self.cfg
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        org = np.asarray(origin, dtype=float)
        member = np.zeros(len(points), dtype=bool)
        clusters, centres, radii = [], [], []
        for idx in segment(points, org, cfg.cluster_gap, angle_increment):
            if len(idx) < cfg.min_points:
                continue
            pts = points[idx]
            extent = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0))))
            if extent > cfg.max_extent:
                continue
            centroid = pts.mean(axis=0)
            ray = centroid - org
            dist = float(np.hypot(*ray))
            if dist > cfg.max_range or dist < 1e-6:
                continue
            radius = min(max(0.5 * extent, 0.05), 0.5 * cfg.max_extent)
            # The visible arc of a round object has its centroid 2r/pi in front of the centre.
            clusters.append(idx)
            centres.append(centroid + ray / dist * (2.0 / math.pi) * radius)
            radii.append(radius)
        # Greedy nearest-neighbour association, closest pairs first.
        assigned: dict[int, int] = {}
        if clusters and self.tracks:
            pred = np.array([t.predict(stamp) for t in self.tracks])
            c = np.asarray(centres)
            d = np.hypot(pred[:, None, 0] - c[None, :, 0], pred[:, None, 1] - c[None, :, 1])
            used_t: set[int] = set()
            for flat in np.argsort(d, axis=None):
                ti, ci = divmod(int(flat), len(clusters))
                if d[ti, ci] > cfg.gate:
                    break
                if ti in used_t or ci in assigned:
                    continue
                used_t.add(ti)
                assigned[ci] = ti
        # A moving track whose prediction missed (it turned round, or merged with a wall for
        # a few scans) takes the nearest unassigned cluster within reach of where it was last
        # seen; its history restarts (old velocity no longer holds) but it stays moving.
        lost = [ti for ti, t in enumerate(self.tracks) if t.moving and ti not in assigned.values()]
        for ci in range(len(clusters)):
            if ci in assigned or not lost:
                continue
            reach = [cfg.gate + float(np.hypot(*self.tracks[ti].velocity)) * (stamp - self.tracks[ti].last_seen)
                     for ti in lost]
            dists = [float(np.hypot(*(self.tracks[ti].position - centres[ci]))) for ti in lost]
            k = int(np.argmin(np.asarray(dists) - np.asarray(reach)))
            if dists[k] <= reach[k]:
                track = self.tracks[lost.pop(k)]
                track.history.clear()
                track.velocity = np.zeros(2)
                assigned[ci] = self.tracks.index(track)
        for ci, idx in enumerate(clusters):
            if ci in assigned:
                track = self.tracks[assigned[ci]]
                track.history.append((stamp, *centres[ci]))
                track.radius = 0.7 * track.radius + 0.3 * radii[ci]
                track.last_seen = stamp
                track.points = points[idx]
                if fresh is not None:
                    track.fresh.append(float(np.mean(fresh[idx])))
                self._fit_velocity(track)
            else:
                track = Track(self._next_id, deque([(stamp, *centres[ci])], maxlen=64), radii[ci], stamp,
                              points=points[idx])
                if fresh is not None:
                    track.fresh.append(float(np.mean(fresh[idx])))
                self._next_id += 1
                self.tracks.append(track)
            if track.moving:
                member[idx] = True
        self.tracks = [t for t in self.tracks if stamp - t.last_seen <= cfg.coast_time]
        return member

    def moving_tracks(self, stamp: float) -> list[Track]:
        return [t for t in self.tracks if t.moving]

    def movers(self, stamp: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centres (M, 2) predicted to ``stamp``, velocities (M, 2), radii (M,)) of the moving tracks."""
        moving = self.moving_tracks(stamp)
        if not moving:
            return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
        return (np.array([t.predict(stamp) for t in moving]), np.array([t.velocity for t in moving]),
                np.array([t.radius for t in moving]))
