"""The cost-to-go grid planner: Dijkstra from the goal over the map's free cells.

Selected by the Planner like an OMPL planner (``planner_id="CostToGo"``). Unlike the sampling
planners it is complete on the grid (no path means none exists at this resolution) and its
paths keep to the middle of corridors (the clearance penalty of :class:`CostField`). The
clearance band is :func:`~.costfield.footprint_field`'s, the one the arc sampler and the
in-process navigator use: cells closer to an obstacle than the robot's inner radius (half the
width of a box) are impassable, a band ``clearance_band`` m beyond is costly, so a gap the
robot fits through is planned through only when nothing wider exists. Unknown cells count as
obstacles with ``unknown_is_occupied``.

A robot that ends up inside the lethal band (pushed, or localized closer to an obstacle than
planning allows) is planned out of it: the path starts with a straight step to the nearest
plannable cell instead of failing with INVALID_START (which left the controller on a stale
plan). :meth:`CostToGoPlanner.block_tightest_spot` puts a temporary block at the tightest
spot of the last plan (a recovery action: the route looked open and is not); blocks are
forgotten when they leave no path.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..maps.grid import OccupancyGridMap
from ..robot import RobotConfig
from .config import OMPLConfig
from .costfield import CENTRING_RANGE, CLEARANCE_BAND, CostField, footprint_field, tightest_spot
from .interpolation import interpolate_se2, path_length
from .result import PlanResult

__all__ = ["GRID_PLANNERS", "CostToGoPlanner", "make_grid_planner"]

#: planner ids of the grid planners (beside OMPL's)
GRID_PLANNERS: tuple[str, ...] = ("CostToGo",)


class CostToGoPlanner:
    """``set_map(grid)`` then ``plan(start, goal)`` -> :class:`PlanResult` (same contract as
    :class:`~emos.actors.nav.planning.OMPLGeometricPlanner`)."""

    name = "CostToGo"

    def __init__(self, robot: RobotConfig, config: OMPLConfig | None = None, inflation: float = CENTRING_RANGE,
                 clearance_band: float = CLEARANCE_BAND) -> None:
        self.robot = robot
        self.config = config or OMPLConfig()
        self.inflation = float(inflation)
        self.clearance_band = float(clearance_band)
        self.grid: OccupancyGridMap | None = None
        self._occupied: np.ndarray | None = None
        self._field: CostField | None = None
        self.blocks: list[tuple[float, float]] = []  # temporary blocks (world x, y)
        self.last_path: np.ndarray | None = None
        self._extra_cost: np.ndarray | None = None

    def set_extra_cost(self, cost: np.ndarray | None) -> None:
        """A soft cost per cell of the map (its shape, finite, >= 0; None: none) that plans avoid
        where they can: a cell of cost c costs 1 + c times its length (e.g. where people walk,
        :mod:`emos.actors.nav.costmap.people`). Kept until replaced; dropped by a map of another shape."""
        if cost is None:
            self._extra_cost = None
            return
        cost = np.asarray(cost, dtype=float)
        if self.grid is not None and cost.shape != self.grid.data.shape:
            raise ValueError(f"CostToGoPlanner.set_extra_cost: expected the map's shape {self.grid.data.shape}, got {cost.shape}")
        if not np.all(np.isfinite(cost)) or (cost < 0).any():
            raise ValueError("CostToGoPlanner.set_extra_cost: costs must be finite and >= 0")
        self._extra_cost = cost

    def set_map(self, grid: OccupancyGridMap) -> None:
        cfg = self.config
        self.grid = grid
        self._occupied = grid.occupied_mask(cfg.occupied_threshold, unknown_is_occupied=cfg.unknown_is_occupied)
        shape = grid.data.shape
        if self._field is None or self._field.shape != shape or self._field.resolution != grid.resolution:
            self._field = footprint_field(shape, grid.resolution, self.robot.inner_radius, self.clearance_band, self.inflation)
        if self._extra_cost is not None and self._extra_cost.shape != shape:
            self._extra_cost = None

    def _with_blocks(self) -> np.ndarray:
        assert self.grid is not None and self._occupied is not None
        if not self.blocks:
            return self._occupied
        occupied = self._occupied.copy()
        # A disc of 5 cm around each block: with the lethal band around it this closes the spot.
        a = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        ring = np.c_[0.05 * np.cos(a), 0.05 * np.sin(a)]
        pts = (np.asarray(self.blocks, dtype=float)[:, None, :] + np.vstack([[0.0, 0.0], ring])[None]).reshape(-1, 2)
        cells = self.grid.world_to_grid(pts)
        inside = self.grid.in_bounds(cells)
        occupied[cells[inside, 1], cells[inside, 0]] = True
        return occupied

    def block_tightest_spot(self, robot_xy: Sequence[float], ahead: float = 2.5) -> tuple[float, float] | None:
        """Block the tightest spot of the next ``ahead`` m of the last plan (never within
        reach of the robot); the next :meth:`plan` routes elsewhere. Returns the spot."""
        if self.last_path is None or self._field is None or self.grid is None:
            return None
        grid, field = self.grid, self._field

        def clearance_at(xy: np.ndarray) -> np.ndarray:
            cells = grid.world_to_grid(xy)
            ok = grid.in_bounds(cells)
            out = np.full(len(xy), np.inf)
            out[ok] = field.clearance[cells[ok, 1], cells[ok, 0]]
            return out

        spot = tightest_spot(self.last_path, clearance_at, robot_xy, self.robot.radius + 0.15, ahead)
        if spot is not None:
            self.blocks.append(spot)
        return spot

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
        field.compute(self._with_blocks(), g_cell, extra_cost=self._extra_cost)
        if field.clearance[g_cell] <= field.lethal_radius:
            return failed("INVALID_GOAL", f"the goal is within {field.lethal_radius:.2f} m of an obstacle (or in one)")
        escape = field.escape_from(s_cell)
        if escape is None and self.blocks:
            # Our own blocks have boxed the robot in: forget them and plan again.
            self.blocks.clear()
            field.compute(self._occupied, g_cell, extra_cost=self._extra_cost)
            escape = field.escape_from(s_cell)
        if escape is None:
            if field.clearance[s_cell] <= field.lethal_radius:
                return failed("INVALID_START", "the robot is within its radius of an obstacle and no free cell is reachable")
            return failed("NO_SOLUTION", "no free path on the grid connects start and goal")
        cells = field.path_from(escape)
        if escape != s_cell:
            cells = [s_cell, *cells]  # out of the lethal band first, straight to the nearest free cell
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
        if escape == s_cell and np.all(clear[1:-1] > field.lethal_radius):
            xy = smooth
        yaw = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0])) if len(xy) > 1 else np.zeros(1)
        if len(goal) > 2:
            yaw[-1] = float(goal[2])
        path = interpolate_se2(np.column_stack([xy, yaw]), self.config.path_resolution)
        self.last_path = path
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
