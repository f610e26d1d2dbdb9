"""``LayeredCostmap``: static layer + obstacle layer + inflation + costmap filters, in Nav2's order.

The master grid is rebuilt from the static layer on each new map; the obstacle layer (when
scans are added) is merged by maximum, then inflation spreads around every lethal cell, then
the keepout filter raises its zones (filters come after inflation in Nav2, so a keepout zone is
lethal up to its edge and the robot's footprint is kept out by the planner's own clearance).
"""
from __future__ import annotations

import numpy as np

from ..maps.grid import OCCUPIED, OccupancyGridMap
from .config import CostmapConfig
from .filters import KeepoutFilter, SpeedFilter, SpeedLimit, load_filter_mask
from .grid import Costmap2D
from .inflation_layer import InflationLayer
from .obstacle_layer import ObstacleLayer
from .static_layer import StaticLayer

__all__ = ["LayeredCostmap"]


class LayeredCostmap:
    def __init__(self, config: CostmapConfig, footprint_inscribed_radius: float = 0.0) -> None:
        self.config = config
        inscribed = config.inscribed_radius or footprint_inscribed_radius
        self.static = StaticLayer(int(config.lethal_cost_threshold), config.track_unknown_space)
        self.inflation = InflationLayer(config.inflation_radius, config.cost_scaling_factor, inscribed,
                                        config.inflate_unknown)
        self.keepout = KeepoutFilter(load_filter_mask(config.keepout_mask, "keepout")) if config.keepout_mask else None
        self.speed = SpeedFilter(load_filter_mask(config.speed_mask, "speed")) if config.speed_mask else None
        self.obstacles: ObstacleLayer | None = None
        self.grid: OccupancyGridMap | None = None
        self.master: Costmap2D | None = None

    def set_map(self, grid: OccupancyGridMap) -> Costmap2D:
        """A new static map: rebuild the master costmap."""
        if self.obstacles is None or self.obstacles.costs.shape != grid.data.shape:
            self.obstacles = ObstacleLayer(grid)
        self.obstacles.geometry = grid
        self.grid = grid
        return self.update()

    def update(self) -> Costmap2D:
        assert self.grid is not None, "LayeredCostmap.update: call set_map first"
        costs = self.static.costs(self.grid)
        if self.obstacles is not None:
            self.obstacles.update_master(costs)
        self.inflation.update(costs, self.grid.resolution)
        if self.keepout is not None:
            self.keepout.update_master(costs, self.grid)
        self.master = Costmap2D(self.grid, costs)
        return self.master

    def planning_grid(self, grid: OccupancyGridMap) -> OccupancyGridMap:
        """``grid`` with keepout cells occupied: what a planner that inflates by the robot's
        own radius must see so that no path enters a keepout zone."""
        if self.keepout is None:
            return grid
        data = grid.data.copy()
        data[self.keepout.lethal_cells(grid)] = OCCUPIED
        return grid.copy_with(data)

    def keepout_zone_at(self, point: np.ndarray) -> str | None:
        return None if self.keepout is None else self.keepout.zone_at(point)

    def speed_limit_at(self, point: np.ndarray) -> SpeedLimit | None:
        return None if self.speed is None else self.speed.limit_at(point)
