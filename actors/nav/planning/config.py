"""Configuration of the OMPL global planner (the spec's ``ompl`` block plus grid settings)."""
from __future__ import annotations

from typing import Any

import attrs

from emos.config import validators as V

from .registry import planner_spec, resolve_planner_name

__all__ = ["OMPLConfig", "LOG_LEVELS", "OPTIMIZATION_OBJECTIVES"]

LOG_LEVELS = ("DEBUG", "INFO", "WARN", "ERROR", "NONE")
# Objectives the installed binding can build. OMPL's clearance / mechanical-work objectives are
# not exposed. A Python OptimizationObjective subclass *is* dispatched, but was tried and
# rejected: PRM/PRMstar deadlock calling it from their roadmap thread, FMT/BFMT fail with it.
OPTIMIZATION_OBJECTIVES = ("PathLengthOptimizationObjective",)
_KNOWN_OMPL_OBJECTIVES = (
    "MaximizeMinClearanceObjective",
    "MechanicalWorkOptimizationObjective",
    "MinimaxObjective",
    "StateCostIntegralObjective",
)


def _log_level(instance: Any, attribute: attrs.Attribute, value: str) -> None:
    if not isinstance(value, str) or value.upper() not in LOG_LEVELS:
        raise ValueError(f"OMPLConfig.log_level: expected one of {LOG_LEVELS}, got {value!r}")


def _objective(instance: Any, attribute: attrs.Attribute, value: str) -> None:
    if value in OPTIMIZATION_OBJECTIVES:
        return
    if value in _KNOWN_OMPL_OBJECTIVES:
        raise ValueError(
            f"OMPLConfig.optimization_objective: '{value}' is not available through the installed "
            f"ompl binding; available: {', '.join(OPTIMIZATION_OBJECTIVES)}"
        )
    raise ValueError(
        f"OMPLConfig.optimization_objective: unknown objective {value!r}; available: "
        f"{', '.join(OPTIMIZATION_OBJECTIVES)}"
    )


def _planner_id(instance: Any, attribute: attrs.Attribute, value: str) -> None:
    resolve_planner_name(value)  # raises with the list of available planners


@attrs.define
class OMPLConfig:
    """OMPL planning settings. Names and defaults of the first six follow the spec's ``ompl`` block.

    - ``planning_timeout`` (s): give up (solved=False) if no exact solution by then;
      optimizing planners use the whole budget to improve their path.
    - ``simplification_timeout`` (s): time given to OMPL's path simplifier.
    - ``goal_tolerance``: distance in OMPL's SE2 metric (metres + 0.5 x |yaw difference|) at
      which the goal counts as reached.
    - ``planner_params``: OMPL parameter names of the chosen planner, e.g. ``{"range": 0.5}``.
    - ``path_resolution`` (m): spacing of the returned, interpolated path.
    - ``occupied_threshold``: cells with value >= this are obstacles.
    - ``unknown_is_occupied``: plan only through known free space (and inside the map).
    - ``simplify``: run OMPL's simplifier on the raw solution.
    - ``first_solution``: stop at the first exact solution; optimizing planners otherwise use
      the whole ``planning_timeout`` to shorten it.
    """

    log_level: str = attrs.field(default="WARN", validator=_log_level)
    planning_timeout: float = attrs.field(default=10.0, converter=float, validator=V.finite_positive)
    simplification_timeout: float = attrs.field(default=0.01, converter=float, validator=V.finite_non_negative)
    goal_tolerance: float = attrs.field(default=0.01, converter=float, validator=V.finite_positive)
    optimization_objective: str = attrs.field(default="PathLengthOptimizationObjective", validator=_objective)
    planner_id: str = attrs.field(default="ompl.geometric.KPIECE1", validator=_planner_id)
    planner_params: dict[str, Any] = attrs.field(factory=dict)
    path_resolution: float = attrs.field(default=0.05, converter=float, validator=V.finite_positive)
    occupied_threshold: int = attrs.field(default=65, validator=V.number(ge=0, le=100, integer=True))
    unknown_is_occupied: bool = attrs.field(default=True, converter=bool)
    simplify: bool = attrs.field(default=True, converter=bool)
    first_solution: bool = attrs.field(default=False, converter=bool)

    @planner_params.validator
    def _check_params(self, attribute: attrs.Attribute, value: dict[str, Any]) -> None:
        if not isinstance(value, dict):
            raise TypeError(f"OMPLConfig.planner_params: expected a dict, got {type(value).__name__}")
        planner_spec(self.planner_id).validate(value)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> OMPLConfig:
        """Build from a config-file mapping such as the spec's ``ompl:`` YAML block."""
        if not isinstance(values, dict):
            raise TypeError(f"OMPLConfig.from_dict: expected a mapping, got {type(values).__name__}")
        known = [f.name for f in attrs.fields(cls)]
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ValueError(f"OMPLConfig: unknown key(s) {unknown}; valid keys: {known}")
        return cls(**values)

    @property
    def planner_name(self) -> str:
        """Short OMPL class name of the chosen planner (e.g. ``"KPIECE1"``)."""
        return resolve_planner_name(self.planner_id)
