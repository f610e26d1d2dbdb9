"""The simulator's own navigator: lidar-built obstacle memory, Dijkstra cost-to-go from the
goal (global plan), and a sampled-arc local planner. No map is given; it only sees the world
through its lidar, as a BARN entry would.
"""
from __future__ import annotations

import math

import numpy as np

from .arcs import ArcConfig, ArcPlanner
from .costfield import CostField
from .grid import HitGrid
from .interface import NavTask, Observation

UNREACHABLE = 1e3  # metres-equivalent cost of ending an arc where the field has no path


class GridNavigator:
    name = "builtin"

    def __init__(self, resolution: float = 0.05, window_margin: float = 3.0, replan_period: float = 0.5,
                 arc_config: ArcConfig | None = None) -> None:
        self.resolution, self.window_margin, self.replan_period = resolution, window_margin, replan_period
        self.arc_config = arc_config
        self.plan: np.ndarray | None = None
        self.task: NavTask | None = None

    def reset(self, task: NavTask) -> None:
        self.task = task
        spec = task.robot
        sx, sy, _ = task.start
        gx, gy = task.goal
        m = self.window_margin
        bounds = (min(sx, gx) - m, min(sy, gy) - m, max(sx, gx) + m, max(sy, gy) + m)
        self.grid = HitGrid(bounds, self.resolution)
        # Lethal a bit under the half-width: the grid blurs hit points by up to half a cell,
        # and the arc planner checks the exact footprint anyway.
        lethal = max(spec.width / 2 - self.resolution * 0.8, 0.05)
        self.field = CostField(self.grid.shape, self.resolution, lethal, inflation_radius=lethal + 0.45)
        self.arcs = ArcPlanner(spec, self.arc_config)
        self._goal_cell = self._cell((gx, gy))
        self._planned_version = -1
        self._last_plan = -math.inf
        self.plan = None

    def _cell(self, xy: tuple[float, float]) -> tuple[int, int]:
        rows, cols, _ = self.grid.cell_of(np.array([xy]))
        return (int(np.clip(rows[0], 0, self.grid.shape[0] - 1)), int(np.clip(cols[0], 0, self.grid.shape[1] - 1)))

    def cost_to_go(self, xy: np.ndarray) -> np.ndarray:
        rows, cols, inside = self.grid.cell_of(xy)
        rows = np.clip(rows, 0, self.grid.shape[0] - 1)
        cols = np.clip(cols, 0, self.grid.shape[1] - 1)
        ctg = self.field.ctg[rows, cols]
        # Outside the window: straight-line distance to the goal plus a penalty.
        straight = np.hypot(xy[:, 0] - self.task.goal[0], xy[:, 1] - self.task.goal[1])  # type: ignore[union-attr]
        ctg = np.where(inside, ctg, straight + 5.0)
        return np.where(np.isfinite(ctg), ctg, UNREACHABLE)

    def _replan(self, obs: Observation) -> None:
        self.field.compute(self.grid.occupied, self._goal_cell)
        self._planned_version = self.grid.version
        self._last_plan = obs.stamp
        cells = self.field.path_from(self._cell((obs.pose[0], obs.pose[1])))
        if cells:
            rc = np.asarray(cells)
            self.plan = self.grid.center_of(rc[:, 0], rc[:, 1])

    def step(self, obs: Observation) -> tuple[float, float, float]:
        if obs.scan is not None:
            self.grid.insert(obs.scan.world_points())
        stale = self.grid.version != self._planned_version
        if self._planned_version < 0 or (stale and obs.stamp - self._last_plan >= self.replan_period):
            self._replan(obs)
        reach = self.arcs.cfg.horizon * self.arcs.cfg.max_speed + self.task.robot.circumscribed_radius + 0.3  # type: ignore[union-attr]
        points = self.grid.points_near((obs.pose[0], obs.pose[1]), reach)
        choice = self.arcs.choose(obs.pose, points, self.cost_to_go)
        if choice is None:
            # Boxed in (nothing clear, not even turning): creep backwards.
            return (-0.1, 0.0, 0.0)
        v, w = choice
        return (v, 0.0, w)
