"""The cost-to-go grid planner: Dijkstra from the goal over the map's free cells.

Selected by the Planner like an OMPL planner (``planner_id="CostToGo"``). Unlike the sampling
planners it is complete on the grid (no path means none exists at this resolution) and its
paths keep to the middle of corridors (the clearance penalty of :class:`CostField`). Cells
within the robot's radius (plus half a cell, since obstacles fill their cells) of an
obstacle are impassable; unknown cells count as obstacles with ``unknown_is_occupied``.
"""
from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np

from ..maps.grid import OccupancyGridMap
from ..robot import RobotConfig
from .config import OMPLConfig
from .costfield import CostField
from .interpolation import interpolate_se2, path_length
from .result import PlanResult

__all__ = ["GRID_PLANNERS", "CostToGoPlanner", "make_grid_planner"]

#: planner ids of the grid planners (beside OMPL's)
GRID_PLANNERS: tuple[str, ...] = ("CostToGo",)


class CostToGoPlanner:
    """``set_map(grid)`` then ``plan(start, goal)`` -> :class:`PlanResult` (same contract as
    :class:`~emos.actors.nav.planning.OMPLGeometricPlanner`)."""

    name = "CostToGo"

    def __init__(self, robot: RobotConfig, config: OMPLConfig | None = None, inflation: float = 0.45) -> None:
        self.robot = robot
        self.config = config or OMPLConfig()
        self.inflation = float(inflation)
        self.grid: OccupancyGridMap | None = None
        self._occupied: np.ndarray | None = None
        self._field: CostField | None = None

    def set_map(self, grid: OccupancyGridMap) -> None:
        cfg = self.config
        self.grid = grid
        self._occupied = grid.occupied_mask(cfg.occupied_threshold, unknown_is_occupied=cfg.unknown_is_occupied)
        lethal = self.robot.radius + 0.5 * grid.resolution
        self._field = CostField(grid.data.shape, grid.resolution, lethal, inflation_radius=lethal + self.inflation,
                                soft_radius=lethal)

    def cancel(self) -> bool:
        return False  # one Dijkstra is a single C call; nothing to interrupt

    def _cell(self, name: str, xy: Sequence[float]) -> tuple[int, int]:
        assert self.grid is not None
        x, y = float(xy[0]), float(xy[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"plan: {name} ({x}, {y}) is not finite")
        ix, iy = self.grid.world_to_grid(np.array([x, y]))
        if not self.grid.in_bounds(np.array([ix, iy])):
            xmin, ymin, xmax, ymax = self.grid.world_bounds()
            raise ValueError(f"plan: {name} ({x:.3f}, {y:.3f}) is outside the map [{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}]")
        return int(iy), int(ix)

    def plan(self, start: Sequence[float], goal: Sequence[float], *, timeout: float | None = None) -> PlanResult:
        if self.grid is None or self._field is None or self._occupied is None:
            raise RuntimeError("CostToGoPlanner.plan: call set_map(grid) first")
        t0 = time.perf_counter()
        s_cell, g_cell = self._cell("start", start), self._cell("goal", goal)

        def failed(status: str, message: str) -> PlanResult:
            return PlanResult(False, np.zeros((0, 3)), self.name, status, time.perf_counter() - t0, 0.0, 0.0, message)

        field = self._field
        field.compute(self._occupied, g_cell)
        if field.clearance[g_cell] <= field.lethal_radius:
            return failed("INVALID_GOAL", f"the goal is within {field.lethal_radius:.2f} m of an obstacle (or in one)")
        cells = field.path_from(s_cell)
        if not cells:
            if field.clearance[s_cell] <= field.lethal_radius:
                return failed("INVALID_START", "the robot is within its radius of an obstacle at the start")
            return failed("NO_SOLUTION", "no free path on the grid connects start and goal")
        ij = np.asarray(cells)[:, ::-1]  # (row, col) -> (ix, iy)
        xy = self.grid.grid_to_world(ij)
        xy[0] = np.asarray(start, dtype=float)[:2]
        xy[-1] = np.asarray(goal, dtype=float)[:2]
        smooth = _shortcut_corners(xy)
        # Keep the smoothing only where it stays as clear of obstacles as the grid path.
        cells_s = self.grid.world_to_grid(smooth)
        inside = self.grid.in_bounds(cells_s)
        clear = np.zeros(len(smooth))
        clear[inside] = field.clearance[cells_s[inside, 1], cells_s[inside, 0]]
        if np.all(clear[1:-1] > field.lethal_radius):
            xy = smooth
        yaw = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0])) if len(xy) > 1 else np.zeros(1)
        if len(goal) > 2:
            yaw[-1] = float(goal[2])
        path = interpolate_se2(np.column_stack([xy, yaw]), self.config.path_resolution)
        return PlanResult(True, path, self.name, "EXACT_SOLUTION", time.perf_counter() - t0, 0.0, path_length(path))


def _shortcut_corners(xy: np.ndarray, window: int = 3) -> np.ndarray:
    """Light smoothing of the 8-connected staircase (moving average, ends fixed)."""
    if len(xy) <= 2 * window:
        return xy
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    out = xy.copy()
    for k in range(2):
        padded = np.concatenate([np.full(window, xy[0, k]), xy[:, k], np.full(window, xy[-1, k])])
        out[:, k] = np.convolve(padded, kernel, mode="valid")
    out[0], out[-1] = xy[0], xy[-1]
    return out


def make_grid_planner(planner_id: str, robot: RobotConfig, config: OMPLConfig | None = None) -> Any:
    if planner_id not in GRID_PLANNERS:
        raise ValueError(f"unknown grid planner {planner_id!r}; grid planners: {', '.join(GRID_PLANNERS)}")
    return CostToGoPlanner(robot, config)
