"""Trajectory cost evaluation for sampling-based controllers."""
from .kernels import (
    CostBreakdown,
    evaluate_costs,
    goal_cost,
    jerk_cost,
    min_obstacle_distance,
    obstacles_cost,
    path_length,
    reference_path_cost,
    smoothness_cost,
)
from .path_distance import PathDistanceField, polyline_distance_exact, simplify_polyline
from .weights import TrajectoryCostsWeights

__all__ = [
    "CostBreakdown",
    "PathDistanceField",
    "TrajectoryCostsWeights",
    "evaluate_costs",
    "goal_cost",
    "jerk_cost",
    "min_obstacle_distance",
    "obstacles_cost",
    "path_length",
    "polyline_distance_exact",
    "reference_path_cost",
    "simplify_polyline",
    "smoothness_cost",
]
