"""Layered 2D costmaps as Nav2 builds them: static, obstacle and inflation layers, keepout and
speed-limit filters from mask maps, and the simple path smoother checked against them.

Pure numpy (no processes): the Planner wires a global costmap to its map and publishes it.
"""
from .config import CostmapConfig, SmootherConfig
from .costs import (
    FREE_SPACE,
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    MAX_NON_OBSTACLE,
    NO_INFORMATION,
    costs_to_occupancy,
    occupancy_to_costs,
)
from .filters import FILTER_TYPES, FilterMask, FilterMaskError, KeepoutFilter, KeepoutObstacles, SpeedFilter, SpeedLimit, load_filter_mask
from .grid import Costmap2D
from .inflation_layer import InflationLayer, inflation_cost
from .layered import LayeredCostmap
from .obstacle_layer import ObstacleLayer
from .people import PeopleLayerConfig, band_grid, people_cost, walked_points
from .smoother import smooth_path
from .static_layer import StaticLayer
from .zones import ZONE_KINDS, Zone, points_in_polygon, rasterize, zone_from_dict

__all__ = [
    "FREE_SPACE", "INSCRIBED_INFLATED_OBSTACLE", "LETHAL_OBSTACLE", "MAX_NON_OBSTACLE", "NO_INFORMATION",
    "FILTER_TYPES", "ZONE_KINDS", "Costmap2D", "CostmapConfig", "FilterMask", "FilterMaskError", "InflationLayer",
    "KeepoutFilter", "KeepoutObstacles", "LayeredCostmap", "ObstacleLayer", "PeopleLayerConfig", "SmootherConfig", "SpeedFilter", "SpeedLimit", "StaticLayer",
    "Zone", "costs_to_occupancy", "inflation_cost", "load_filter_mask", "occupancy_to_costs", "points_in_polygon",
    "band_grid", "people_cost", "rasterize", "smooth_path", "walked_points", "zone_from_dict",
]
