"""Planner comparison table on the shipped ``rooms`` map (the spec's planning benchmark).

Every OMPL geometric planner the binding exposes solves the same query, from the south-west
room to the north-east room through two doorways, for a cylinder robot of radius 0.25 m,
with a fixed time budget. Anytime/optimizing planners (RRT*, BIT*, PRM, ...) use the whole
budget to improve their path, so their time is the budget; feasibility planners (RRTConnect,
KPIECE1, ...) stop at their first solution.

``run_planning_table`` is imported by ``emos bench nav``; run this module directly for a
stand-alone table: ``python -m emos.tools.bench.nav_planning [--budget 1.0] [--json]``.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
from typing import Any

import numpy as np

from emos.actors.nav.data import ROOMS_MAP_YAML
from emos.actors.nav.maps import load_map
from emos.actors.nav.planning import OMPLConfig, OMPLGeometricPlanner, available_planners, resolve_planner_name
from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType

__all__ = ["BENCH_START", "BENCH_GOAL", "run_planning_table", "format_table", "main"]

#: Query on the rooms map (world frame): SW room -> NE room, two doorways on the way.
BENCH_START = (-4.0, -4.0, 0.0)
BENCH_GOAL = (2.0, 2.0, math.pi / 2)


def _bench_robot() -> RobotConfig:
    return RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE,
        geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.25, 0.3]),
    )


def run_planning_table(
    budget_s: float = 1.0, planners: list[str] | None = None, repeats: int = 1
) -> list[dict[str, Any]]:
    """Plan the benchmark query with each planner; one row per planner.

    Row: ``{"planner", "solved", "time_s", "length_m", "simplification_time_s"}``. With
    ``repeats`` > 1 the numbers are means over the solved runs and ``solved`` is True only if
    every run solved. ``length_m`` and ``simplification_time_s`` are None when nothing solved.
    """
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"run_planning_table: budget_s must be > 0, got {budget_s!r}")
    if repeats < 1:
        raise ValueError(f"run_planning_table: repeats must be >= 1, got {repeats!r}")
    names = [resolve_planner_name(p) for p in planners] if planners else available_planners()
    grid = load_map(ROOMS_MAP_YAML)
    robot = _bench_robot()
    rows: list[dict[str, Any]] = []
    for name in names:
        planner = OMPLGeometricPlanner(OMPLConfig(planner_id=name, planning_timeout=budget_s), robot)
        planner.set_map(grid)
        results = [planner.plan(BENCH_START, BENCH_GOAL) for _ in range(repeats)]
        ok = [r for r in results if r.solved]
        rows.append(
            {
                "planner": name,
                "solved": len(ok) == len(results),
                "time_s": statistics.fmean(r.planning_time_s for r in results),
                "length_m": statistics.fmean(r.length_m for r in ok) if ok else None,
                "simplification_time_s": statistics.fmean(r.simplification_time_s for r in ok) if ok else None,
            }
        )
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    """Markdown table in the spec's layout."""

    def num(v: Any, fmt: str) -> str:
        return "--" if v is None else format(v, fmt)

    lines = [
        "| Planner | Solved | Solution time (s) | Path length (m) | Simplification time (s) |",
        "|:---|:---|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['planner']} | {r['solved']} | {r['time_s']:.3f} | {num(r['length_m'], '.2f')} | "
            f"{num(r['simplification_time_s'], '.4f')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=1.0, help="seconds per planner (default 1.0)")
    parser.add_argument("--repeats", type=int, default=1, help="queries per planner (default 1)")
    parser.add_argument("--planners", nargs="*", default=None, help="planner ids (default: all available)")
    parser.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    args = parser.parse_args(argv)
    rows = run_planning_table(args.budget, args.planners, args.repeats)
    print(json.dumps(rows) if args.json else format_table(rows))
    return 0 if all(r["solved"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
