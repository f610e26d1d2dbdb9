"""Static layer: the map's cells as costs (Nav2 ``StaticLayer`` parameters)."""
from __future__ import annotations

import numpy as np

from ..maps.grid import OccupancyGridMap
from .costs import FREE_SPACE, NO_INFORMATION, occupancy_to_costs

__all__ = ["StaticLayer"]


class StaticLayer:
    """``lethal_cost_threshold`` (0..100, default 100), ``track_unknown_space`` (unknown cells stay
    255, else free), ``trinary_costmap`` (True: free or lethal; False: map values scaled)."""

    def __init__(self, lethal_cost_threshold: int = 100, track_unknown_space: bool = True,
                 trinary_costmap: bool = True) -> None:
        if isinstance(lethal_cost_threshold, bool) or not isinstance(lethal_cost_threshold, int) \
                or not 0 <= lethal_cost_threshold <= 100:
            raise ValueError(f"StaticLayer: lethal_cost_threshold must be an integer 0..100, got {lethal_cost_threshold!r}")
        self.lethal_cost_threshold = lethal_cost_threshold
        self.track_unknown_space = bool(track_unknown_space)
        self.trinary_costmap = bool(trinary_costmap)

    def costs(self, grid: OccupancyGridMap) -> np.ndarray:
        unknown = NO_INFORMATION if self.track_unknown_space else FREE_SPACE
        return occupancy_to_costs(grid.data, self.lethal_cost_threshold, unknown, self.trinary_costmap)
