"""Localization-only mode: scan matching against a saved map that is never changed (what
slam_toolbox's localization mode and Cartographer's pure localization give a ROS user).

:class:`MapLocalizer` holds one :class:`LikelihoodGrid` of the whole saved map, built once from
either

- the Mapper's own saved pose graph (:mod:`store`, ``NAME.posegraph.npz``): every node's scan
  hits placed at its optimised pose (the same hits the SLAM matched against), or
- a ROS map_server YAML + PGM: the centres of its occupied cells.

Each scan, :meth:`MapLocalizer.step`: the odometry increment carries the last pose to a guess;
the scan's hits are matched against the map by :class:`CorrelativeMatcher` in a window of
``window_sigmas`` standard deviations of the odometry noise model around the guess, with the
SLAM's weak prior towards the guess (so that along a featureless corridor the odometry decides).
A match whose score reaches ``min_score`` gives the pose; otherwise the pose follows the
odometry and the scan counts as *unmatched* (``lost`` after ``lost_after`` of them in a row).
Nothing is ever inserted into the grid: the map a robot localizes in stays the map it was given
(:attr:`MapLocalizer.map_digest` lets a caller check that).

Per-scan cost is the SLAM front end's: bounded by the window and the hit count (the matcher
pools only the crop of the grid around the scan), never by the size of the map.
"""
from __future__ import annotations

import hashlib
import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from emos.ratelimit import RateLimitedLog

from ...localization.motion import compose_pose, relative_pose
from ...maps import load_map
from .grid import LikelihoodGrid
from .matcher import CorrelativeMatcher, MatchResult, voxel_filter
from .slam import GraphSlam, SlamParams, scan_points
from .store import POSEGRAPH_SUFFIX, load_posegraph

__all__ = ["MapLocalizer", "map_grid"]

_log = logging.getLogger("emos.nav.mapping.relocalize")


def map_grid(path: str | os.PathLike, params: SlamParams) -> tuple[LikelihoodGrid, np.ndarray, Any]:
    """The likelihood grid of a saved map, the pose the map frame's first node had (the origin
    for a YAML map) and what was loaded (a ``PoseGraphFile`` or an ``OccupancyGridMap``).
    ``path``: ``*.posegraph.npz`` or a map_server ``*.yaml``; anything else is a ValueError
    naming the file."""
    p = Path(path)
    if p.name.endswith(POSEGRAPH_SUFFIX):
        graph = load_posegraph(p)
        grid = LikelihoodGrid(graph.resolution, graph.sigma, margin=5.0)
        for pose, r, a in zip(graph.poses, graph.ranges, graph.angles):
            local = scan_points(r, a, graph.min_range, graph.max_range)
            if not len(local):
                continue
            c, s = math.cos(pose[2]), math.sin(pose[2])
            grid.insert(np.column_stack([c * local[:, 0] - s * local[:, 1] + pose[0],
                                         s * local[:, 0] + c * local[:, 1] + pose[1]]))
        return grid, graph.poses[0].copy(), graph
    if p.suffix.lower() in (".yaml", ".yml"):
        occ = load_map(p)
        cells = np.argwhere(occ.occupied_mask())  # (row, col)
        if not len(cells):
            raise ValueError(f"{p}: the map has no occupied cell: nothing to localize against")
        grid = LikelihoodGrid(params.resolution, params.sigma, margin=5.0)
        grid.insert(occ.grid_to_world(cells[:, ::-1]))
        return grid, np.zeros(3), occ
    raise ValueError(f"{p}: expected a saved pose graph (*{POSEGRAPH_SUFFIX}) or a map_server YAML (*.yaml)")


class MapLocalizer:
    """Scan-to-map localization on a fixed map (module docstring). ``start``: the first scan's
    pose in the map (default: the saved graph's first node, or the map origin for a YAML map);
    :meth:`reset` moves it (an initial pose)."""

    def __init__(self, map_file: str | os.PathLike, params: SlamParams | None = None, *, start: Any = None,
                 min_score: float = 0.3, lost_after: int = 5, name: str = "map localizer",
                 logger: logging.Logger | None = None) -> None:
        self.params = params or SlamParams()
        self.name = name
        self.min_score = float(min_score)
        self.lost_after = int(lost_after)
        self._logger = logger or _log
        self._report = RateLimitedLog(interval=5.0)
        self.grid, first, self.source = map_grid(map_file, self.params)
        self.map_file = str(map_file)
        self.map_digest = self.digest()
        # The SLAM's odometry noise model sizes the search window; its input checks name the scan.
        self._model = GraphSlam(self.params, name=name, logger=self._logger)
        self.matcher = CorrelativeMatcher()
        self.pose = np.asarray(first if start is None else start, dtype=np.float64).reshape(3).copy()
        self._odom: np.ndarray | None = None
        self._seek = False
        self.scans = 0
        self.matched = 0
        self.unmatched_run = 0
        self.last_match: MatchResult | None = None

    def digest(self) -> str:
        """SHA-1 of the likelihood field: equal before and after localizing (the map is read only)."""
        return hashlib.sha1(self.grid.data.tobytes() + self.grid.origin.tobytes()).hexdigest()

    @property
    def lost(self) -> bool:
        return self.unmatched_run >= self.lost_after

    @property
    def problems(self) -> dict[str, int]:
        return self._model.problems

    def reset(self, pose: Any) -> None:
        """Put the robot at ``pose`` (x, y, yaw, map frame) for the next scan; that scan is
        searched in the widest window (the given pose is a guess)."""
        p = np.asarray(pose, dtype=np.float64).reshape(3)
        if not np.isfinite(p).all():
            raise ValueError(f"{self.name}: initial pose must be finite (x, y, yaw), got {p.tolist()}")
        self.pose = p.copy()
        self._seek = True
        self.unmatched_run = 0

    def step(self, odom_pose: Any, ranges: Any, angles: Any) -> np.ndarray:
        """One scan taken at odometry pose ``odom_pose``; returns the pose in the map."""
        p = self.params
        odom = np.asarray(odom_pose, dtype=np.float64).reshape(3)
        if not np.isfinite(odom).all():
            self._model._problem("odom", "%s: scan %d has a non-finite odometry pose %s; holding the last one",
                                 self.name, self.scans, odom.tolist())
            odom = self._odom.copy() if self._odom is not None else np.zeros(3)
        delta = np.zeros(3) if self._odom is None else relative_pose(self._odom, odom)
        self._odom = odom
        guess = compose_pose(self.pose, delta)
        index = self.scans
        self.scans += 1
        pts = self._model._hits(index, ranges, angles)
        near = np.zeros((0, 2)) if pts is None else pts[np.hypot(pts[:, 0], pts[:, 1]) < p.match_range]
        hits = voxel_filter(near, p.voxel)
        self.last_match = None
        if len(hits) >= p.min_points:
            if self._seek or self.lost:
                wxy, wth = p.max_window_xy, p.max_window_theta
            else:
                wxy, wth = self._model._window(delta)
            sd = self._model._odom_cov(delta)
            m = self.matcher.match(self.grid, guess, hits, window_xy=wxy, window_theta=wth, min_score=self.min_score,
                                   prior_weight=0.0 if self._seek else p.prior_weight,
                                   prior_sigma=(max(math.sqrt(max(sd[0, 0], sd[1, 1])), 0.02),
                                                max(math.sqrt(sd[2, 2]), 0.01)))
            if m is not None and m.score >= self.min_score:
                self.pose = m.pose
                self.matched += 1
                self.unmatched_run = 0
                self._seek = False
                self.last_match = m
                return self.pose.copy()
        self.pose = guess
        self.unmatched_run += 1
        if self.lost:
            self._report.warning((self.name, "lost"), "%s: %d scans in a row match the map %s nowhere near the "
                                 "odometry's guess (score < %.2f): following the odometry; give an initial pose",
                                 self.name, self.unmatched_run, self.map_file, self.min_score, logger=self._logger)
        return self.pose.copy()
