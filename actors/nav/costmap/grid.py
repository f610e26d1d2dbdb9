"""``Costmap2D``: a uint8 cost grid on the geometry of an :class:`OccupancyGridMap`."""
from __future__ import annotations

import numpy as np

from ..maps.grid import OccupancyGridMap
from .costs import NO_INFORMATION, costs_to_occupancy

__all__ = ["Costmap2D"]


class Costmap2D:
    """Costs ``costs[iy, ix]`` (Nav2 values, :mod:`.costs`) over the cells of ``geometry``
    (resolution, origin, frame); the geometry's own cell values are not used."""

    def __init__(self, geometry: OccupancyGridMap, costs: np.ndarray | None = None) -> None:
        self.geometry = geometry
        shape = geometry.data.shape
        if costs is None:
            costs = np.zeros(shape, dtype=np.uint8)
        costs = np.asarray(costs)
        if costs.shape != shape:
            raise ValueError(f"Costmap2D: costs of shape {costs.shape} do not match the grid {shape}")
        self.costs = np.ascontiguousarray(costs, dtype=np.uint8)

    @property
    def resolution(self) -> float:
        return self.geometry.resolution

    def cost_at(self, points: np.ndarray, outside: int = NO_INFORMATION) -> np.ndarray:
        """Costs at world points (..., 2); points off the grid get ``outside``."""
        cells = self.geometry.world_to_grid(np.asarray(points, dtype=float))
        inside = self.geometry.in_bounds(cells)
        ix = np.where(inside, cells[..., 0], 0)
        iy = np.where(inside, cells[..., 1], 0)
        return np.where(inside, self.costs[iy, ix], outside).astype(np.uint8)

    def to_occupancy(self) -> np.ndarray:
        """int8 cells for an ``OccupancyGrid`` message (Nav2's translation)."""
        return costs_to_occupancy(self.costs)
