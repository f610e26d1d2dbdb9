"""Global path planning: OMPL geometric planners in SE2 with fcl collision checking."""
from .config import LOG_LEVELS, OPTIMIZATION_OBJECTIVES, OMPLConfig
from .interpolation import interpolate_se2, path_length, wrap_angle
from .planner import OMPLGeometricPlanner
from .registry import (
    SPEC_PLANNERS,
    PlannerNotAvailableError,
    UnknownPlannerError,
    available_planners,
    make_planner,
    resolve_planner_name,
)
from .result import PlanResult

__all__ = [
    "LOG_LEVELS",
    "OPTIMIZATION_OBJECTIVES",
    "OMPLConfig",
    "OMPLGeometricPlanner",
    "PlanResult",
    "PlannerNotAvailableError",
    "SPEC_PLANNERS",
    "UnknownPlannerError",
    "available_planners",
    "interpolate_se2",
    "make_planner",
    "path_length",
    "resolve_planner_name",
    "wrap_angle",
]
