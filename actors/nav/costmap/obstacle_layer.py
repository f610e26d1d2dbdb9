"""Obstacle layer: marks scan hits and clears the cells each beam passes through.

Nav2 ``ObstacleLayer`` semantics and parameter names: a beam marks its end cell lethal when
its range is in [``obstacle_min_range``, ``obstacle_max_range``] and clears (sets free) the
cells it crosses from ``raytrace_min_range`` up to the hit, or up to ``raytrace_max_range``
when it hits nothing (inf or beyond the sensor's range_max). Clearing runs before marking, so a
beam never erases another beam's hit in the same scan. The layer keeps its own grid (255 where
it has seen nothing) and is merged into the master by maximum, so it never clears the static
map's walls: only obstacles it marked itself.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..maps.grid import OccupancyGridMap
from .costs import FREE_SPACE, LETHAL_OBSTACLE, NO_INFORMATION

__all__ = ["ObstacleLayer"]


class ObstacleLayer:
    def __init__(self, geometry: OccupancyGridMap, obstacle_max_range: float = 2.5, obstacle_min_range: float = 0.0,
                 raytrace_max_range: float = 3.0, raytrace_min_range: float = 0.0,
                 marking: bool = True, clearing: bool = True) -> None:
        for name, value in (("obstacle_max_range", obstacle_max_range), ("obstacle_min_range", obstacle_min_range),
                            ("raytrace_max_range", raytrace_max_range), ("raytrace_min_range", raytrace_min_range)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"ObstacleLayer: {name} must be a finite distance >= 0 m, got {value!r}")
        self.geometry = geometry
        self.obstacle_max_range, self.obstacle_min_range = float(obstacle_max_range), float(obstacle_min_range)
        self.raytrace_max_range, self.raytrace_min_range = float(raytrace_max_range), float(raytrace_min_range)
        self.marking, self.clearing = bool(marking), bool(clearing)
        self.costs = np.full(geometry.data.shape, NO_INFORMATION, dtype=np.uint8)

    def reset(self) -> None:
        """Forget every mark (Nav2's clear-costmap service)."""
        self.costs.fill(NO_INFORMATION)

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cells = self.geometry.world_to_grid(xy)
        inside = self.geometry.in_bounds(cells)
        return cells[inside, 1], cells[inside, 0]

    def add_scan(self, sensor_pose: Sequence[float], ranges: np.ndarray, angle_min: float, angle_increment: float,
                 range_max: float = math.inf) -> None:
        """One LaserScan taken at ``sensor_pose`` (x, y, yaw in the costmap's frame). NaN beams
        are skipped; inf (or > ``range_max``) beams only clear."""
        r = np.asarray(ranges, dtype=float).reshape(-1)
        x0, y0, yaw0 = (float(v) for v in sensor_pose)
        if not all(math.isfinite(v) for v in (x0, y0, yaw0, angle_min, angle_increment)):
            raise ValueError(f"ObstacleLayer.add_scan: sensor pose and angles must be finite, got {sensor_pose!r}, "
                             f"angle_min={angle_min!r}, angle_increment={angle_increment!r}")
        angles = yaw0 + angle_min + angle_increment * np.arange(len(r))
        valid = ~np.isnan(r)
        hit = valid & np.isfinite(r) & (r <= range_max)
        direction = np.column_stack([np.cos(angles), np.sin(angles)])
        if self.clearing:
            length = np.where(hit, np.minimum(r, self.raytrace_max_range), self.raytrace_max_range)
            length = np.where(valid, length, 0.0)
            step = self.geometry.resolution / 2.0
            n = int(math.ceil(float(length.max(initial=0.0)) / step)) + 1
            t = np.arange(n) * step
            # Stop half a cell short of a hit so its own cell is left to marking.
            stop = np.where(hit & (r <= self.raytrace_max_range), length - step, length)
            use = (t[None, :] >= self.raytrace_min_range) & (t[None, :] <= stop[:, None])
            pts = np.array([x0, y0]) + direction[:, None, :] * t[None, :, None]
            rows, cols = self._cells(pts[use])
            self.costs[rows, cols] = FREE_SPACE
        if self.marking:
            mark = hit & (r >= self.obstacle_min_range) & (r <= self.obstacle_max_range)
            pts = np.array([x0, y0]) + direction[mark] * r[mark, None]
            rows, cols = self._cells(pts)
            self.costs[rows, cols] = LETHAL_OBSTACLE

    def update_master(self, master: np.ndarray) -> np.ndarray:
        """Nav2's ``updateWithMax``: known layer cells raise the master (unknown master cells take them)."""
        known = self.costs != NO_INFORMATION
        take = known & ((master == NO_INFORMATION) | (master < self.costs))
        master[take] = self.costs[take]
        return master
