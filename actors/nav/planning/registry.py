"""Which OMPL geometric planners exist, how they are named, and how their parameters are set.

The pip ``ompl`` 2.x binding cannot return a planner's ``ParamSet`` (``planner.params()``
fails to convert), so parameters are applied through the typed setters the binding does
expose. Parameter names are OMPL's own (the names the spec lists under "Planner Default
Parameters"); a name the planner does not know is an error that lists the valid ones.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import attrs

from emos.errors import ConfigError, EmosError

__all__ = [
    "SPEC_PLANNERS",
    "PlannerSpec",
    "PlannerNotAvailableError",
    "UnknownPlannerError",
    "available_planners",
    "planner_spec",
    "resolve_planner_name",
    "make_planner",
]

# The planners the EMOS spec lists (navigation "Available OMPL Planners").
SPEC_PLANNERS: tuple[str, ...] = (
    "ABITstar", "AITstar", "BFMT", "BITstar", "BKPIECE1", "BiEST", "EST", "FMT",
    "InformedRRTstar", "KPIECE1", "LBKPIECE1", "LBTRRT", "LazyLBTRRT", "LazyPRM",
    "LazyPRMstar", "LazyRRT", "PDST", "PRM", "PRMstar", "ProjEST", "RRT", "RRTConnect",
    "RRTXstatic", "RRTsharp", "RRTstar", "SBL", "SST", "STRIDE", "TRRT",
)


class UnknownPlannerError(ConfigError):
    """A planner id that names no OMPL geometric planner at all."""


class PlannerNotAvailableError(EmosError, ValueError):
    """A planner EMOS knows (from the spec's list) that the installed binding does not expose."""


def _as_bool(name: str, value: Any) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, (int,)) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in ("true", "false", "1", "0"):
        return value.strip().lower() in ("true", "1")
    raise TypeError(f"planner parameter '{name}': expected a boolean, got {value!r}")


def _as_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or float(value) != int(value):
        raise TypeError(f"planner parameter '{name}': expected an integer, got {value!r}")
    if value < 0:
        raise ValueError(f"planner parameter '{name}': expected >= 0, got {value!r}")
    return int(value)


def _as_float(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise TypeError(f"planner parameter '{name}': expected a finite number, got {value!r}")
    if value < 0:
        raise ValueError(f"planner parameter '{name}': expected >= 0, got {value!r}")
    return float(value)


def _fraction(name: str, value: Any) -> float:
    v = _as_float(name, value)
    if v > 1.0:
        raise ValueError(f"planner parameter '{name}': expected a fraction in [0, 1], got {value!r}")
    return v


# param name -> (setter method, converter)
_Param = tuple[str, Callable[[str, Any], Any]]

_RANGE: dict[str, _Param] = {"range": ("setRange", _as_float)}
_GOAL_BIAS: dict[str, _Param] = {"goal_bias": ("setGoalBias", _fraction)}
_RRTSTAR_COMMON: dict[str, _Param] = {
    **_RANGE,
    **_GOAL_BIAS,
    "delay_collision_checking": ("setDelayCC", _as_bool),
    "number_sampling_attempts": ("setNumSamplingAttempts", _as_int),
    "ordered_sampling": ("setOrderedSampling", _as_bool),
    "ordering_batch_size": ("setBatchSize", _as_int),
    "prune_threshold": ("setPruneThreshold", _fraction),
    "rewire_factor": ("setRewireFactor", _as_float),
    "use_k_nearest": ("setKNearest", _as_bool),
}
_FMT_COMMON: dict[str, _Param] = {
    "cache_cc": ("setCacheCC", _as_bool),
    "extended_fmt": ("setExtendedFMT", _as_bool),
    "heuristics": ("setHeuristics", _as_bool),
    "num_samples": ("setNumSamples", _as_int),
    "radius_multiplier": ("setRadiusMultiplier", _as_float),
    "free_space_volume": ("setFreeSpaceVolume", _as_float),
}
_KPIECE_COMMON: dict[str, _Param] = {
    **_RANGE,
    "border_fraction": ("setBorderFraction", _fraction),
    "min_valid_path_fraction": ("setMinValidPathFraction", _fraction),
}


@attrs.define(frozen=True)
class PlannerSpec:
    """One planner: its OMPL class name, its parameters, and spec parameters it cannot take."""

    name: str
    params: dict[str, _Param]
    # Parameters the spec lists for this planner that the binding gives no setter for.
    unsupported: tuple[str, ...] = ()

    def validate(self, values: dict[str, Any]) -> dict[str, Any]:
        """Check names and types of ``values``; return them converted. Unknown names raise."""
        converted: dict[str, Any] = {}
        for key, value in values.items():
            if key not in self.params:
                if key in self.unsupported:
                    raise ValueError(
                        f"planner {self.name}: parameter '{key}' exists in OMPL but the installed "
                        f"binding exposes no setter for it; settable: {sorted(self.params)}"
                    )
                raise ValueError(
                    f"planner {self.name}: unknown parameter '{key}'; valid parameters: "
                    f"{sorted(self.params) or 'none'}"
                )
            converted[key] = self.params[key][1](key, value)
        return converted

    def apply(self, planner: Any, values: dict[str, Any]) -> None:
        """Set every parameter in ``values`` on ``planner`` through its setter."""
        for key, value in self.validate(values).items():
            getattr(planner, self.params[key][0])(value)


_SPECS: dict[str, PlannerSpec] = {
    "RRT": PlannerSpec("RRT", {**_RANGE, **_GOAL_BIAS, "intermediate_states": ("setIntermediateStates", _as_bool)}),
    "RRTConnect": PlannerSpec("RRTConnect", {**_RANGE, "intermediate_states": ("setIntermediateStates", _as_bool)}),
    "RRTstar": PlannerSpec(
        "RRTstar",
        {
            **_RRTSTAR_COMMON,
            "focus_search": ("setFocusSearch", _as_bool),
            "informed_sampling": ("setInformedSampling", _as_bool),
            "new_state_rejection": ("setNewStateRejection", _as_bool),
            "pruned_measure": ("setPrunedMeasure", _as_bool),
            "sample_rejection": ("setSampleRejection", _as_bool),
            "tree_pruning": ("setTreePruning", _as_bool),
            "use_admissible_heuristic": ("setAdmissibleCostToCome", _as_bool),
        },
    ),
    # InformedRRTstar and SORRTstar are RRT* with informed sampling and pruning fixed on;
    # OMPL removes the switches that would undo that, so only the common ones are offered.
    "InformedRRTstar": PlannerSpec("InformedRRTstar", dict(_RRTSTAR_COMMON)),
    "SORRTstar": PlannerSpec("SORRTstar", dict(_RRTSTAR_COMMON)),
    "AORRTC": PlannerSpec("AORRTC", dict(_RANGE)),
    "PRM": PlannerSpec("PRM", {"max_nearest_neighbors": ("setMaxNearestNeighbors", _as_int)}),
    "PRMstar": PlannerSpec("PRMstar", {}),
    "FMT": PlannerSpec("FMT", {**_FMT_COMMON, "use_k_nearest": ("setNearestK", _as_bool)}),
    "BFMT": PlannerSpec(
        "BFMT", {**_FMT_COMMON, "nearest_k": ("setNearestK", _as_bool)}, unsupported=("balanced", "optimality")
    ),
    "BITstar": PlannerSpec(
        "BITstar",
        {
            "delay_rewiring_to_first_solution": ("setDelayRewiringUntilInitialSolution", _as_bool),
            "drop_unconnected_samples_on_prune": ("setDropSamplesOnPrune", _as_bool),
            "find_approximate_solutions": ("setConsiderApproximateSolutions", _as_bool),
            "prune_threshold_as_fractional_cost_change": ("setPruneThresholdFraction", _fraction),
            "rewire_factor": ("setRewireFactor", _as_float),
            "samples_per_batch": ("setSamplesPerBatch", _as_int),
            "stop_on_each_solution_improvement": ("setStopOnSolnImprovement", _as_bool),
            "use_graph_pruning": ("setPruning", _as_bool),
            "use_just_in_time_sampling": ("setJustInTimeSampling", _as_bool),
            "use_k_nearest": ("setUseKNearest", _as_bool),
            "use_strict_queue_ordering": ("setStrictQueueOrdering", _as_bool),
        },
    ),
    "KPIECE1": PlannerSpec(
        "KPIECE1",
        {
            **_KPIECE_COMMON,
            **_GOAL_BIAS,
            "failed_expansion_score_factor": ("setFailedExpansionCellScoreFactor", _fraction),
        },
    ),
    "BKPIECE1": PlannerSpec(
        "BKPIECE1",
        {**_KPIECE_COMMON, "failed_expansion_score_factor": ("setFailedExpansionCellScoreFactor", _fraction)},
    ),
    "LBKPIECE1": PlannerSpec("LBKPIECE1", dict(_KPIECE_COMMON)),
}


def _geometric() -> Any:
    try:
        from ompl import geometric
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("global planning needs the OMPL bindings: pip install 'emos[nav]'") from exc
    return geometric


def available_planners() -> list[str]:
    """Planners that both EMOS wraps and the installed binding exposes, sorted."""
    og = _geometric()
    return sorted(name for name in _SPECS if hasattr(og, name))


def resolve_planner_name(planner_id: str) -> str:
    """``"ompl.geometric.RRTConnect"``, ``"geometric.RRTConnect"`` or ``"RRTConnect"`` -> ``"RRTConnect"``.

    Raises :class:`PlannerNotAvailableError` for a spec planner the binding lacks and
    :class:`UnknownPlannerError` for anything else; both list the available planners.
    """
    if not isinstance(planner_id, str) or not planner_id.strip():
        raise UnknownPlannerError(f"planner_id: expected a planner name, got {planner_id!r}")
    name = planner_id.strip()
    for prefix in ("ompl.geometric.", "geometric.", "og."):
        if name.startswith(prefix):
            name = name[len(prefix):]
            break
    available = available_planners()
    if name in available:
        return name
    lowered = {n.lower(): n for n in available}
    if name.lower() in lowered:
        return lowered[name.lower()]
    if name in SPEC_PLANNERS or name in _SPECS:
        raise PlannerNotAvailableError(
            f"planner '{planner_id}' is in the EMOS planner list but the installed ompl binding "
            f"does not expose it; available planners: {', '.join(available)}"
        )
    raise UnknownPlannerError(
        f"unknown planner '{planner_id}'; available planners: {', '.join(available)}"
    )


def planner_spec(planner_id: str) -> PlannerSpec:
    return _SPECS[resolve_planner_name(planner_id)]


def make_planner(planner_id: str, space_information: Any, params: dict[str, Any] | None = None) -> Any:
    """Instantiate the planner for ``planner_id`` on ``space_information`` and apply ``params``."""
    spec = planner_spec(planner_id)
    # Validate before constructing: OMPL 2.0.1's AORRTC segfaults if it is destroyed before
    # setup(), so a planner must never be built and then dropped because of a bad parameter.
    values = spec.validate(dict(params or {}))
    planner = getattr(_geometric(), spec.name)(space_information)
    for key, value in values.items():
        getattr(planner, spec.params[key][0])(value)
    return planner
