"""Global planners by id for the :class:`Planner`: OMPL's geometric planners, and the grid
planners of :mod:`emos.actors.nav.planning` (selected by name like any OMPL planner)."""
from __future__ import annotations

from typing import Any

import attrs

from ..planning import OMPLConfig, OMPLGeometricPlanner, resolve_planner_name
from ..planning.grid_planner import GRID_PLANNERS, make_grid_planner
from ..robot import RobotConfig

__all__ = ["check_planner_id", "make_global_planner"]


def check_planner_id(planner_id: Any) -> None:
    """Raise naming the valid ids when ``planner_id`` is neither a grid nor an OMPL planner."""
    if isinstance(planner_id, str) and planner_id in GRID_PLANNERS:
        return
    try:
        resolve_planner_name(planner_id)
    except ValueError as exc:
        raise ValueError(f"{exc}; grid planners: {', '.join(GRID_PLANNERS)}") from None


def make_global_planner(planner_id: str, robot: RobotConfig, ompl: OMPLConfig) -> Any:
    """An object with ``set_map(grid)``, ``plan(start, goal, timeout=)`` -> PlanResult, ``cancel()``."""
    if planner_id in GRID_PLANNERS:
        return make_grid_planner(planner_id, robot, ompl)
    return OMPLGeometricPlanner(attrs.evolve(ompl, planner_id=planner_id), robot)
