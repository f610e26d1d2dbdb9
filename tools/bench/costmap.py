"""Keepout benchmark (``emos bench costmap``): seeded planning queries in the house map, each
with a keepout zone placed on the shortest route, planned as the Planner plans (global costmap:
static + inflation + keepout filter, the planner on the keepout-blocked grid). Counts entries of
plans into the zone (goal: 0) and times the planner with and without the costmap layers.

A zone is a square of ``--zone`` m centred on the middle of the route planned without it; start
and goal are at least ``--zone`` m from it. A query whose zone closes the only corridor has no
route: the planner must report that (counted as ``no_route``), never plan through.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_arguments", "run", "measure"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--queries", type=int, default=200, help="planning queries (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--planner", default="CostToGo", help="planner id (default CostToGo; any OMPL id works)")
    parser.add_argument("--zone", type=float, default=0.6, help="keepout square side, m (default 0.6)")
    parser.add_argument("--drive", type=int, default=0, metavar="LEGS",
                        help="drive LEGS seeded mission legs through the processes in the simulated house instead "
                             "(ground truth entries; tools/bench/costmap_drive.py)")
    parser.add_argument("--scope", choices=("stack", "local"), default="stack",
                        help="with --drive: zones on the whole stack (use_zones), or on the Controller and "
                             "DriveManager only (the Planner's plans cross them)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def _house() -> Any:
    from emos.actors.nav.maps import load_map
    from emos.packages import get_package_share_directory

    return load_map(os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_gazebo_house.yaml"))


def _dense(path: np.ndarray, step: float = 0.01) -> np.ndarray:
    """The path's polyline sampled every ``step`` m (an entry between two poses counts too)."""
    xy = path[:, :2]
    out = [xy[:1]]
    for a, b in zip(xy[:-1], xy[1:]):
        n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.vstack(out)


def measure(queries: int = 200, seed: int = 0, planner_id: str = "CostToGo", zone_side: float = 0.6) -> dict[str, Any]:
    from emos.actors.nav.components.planners import make_global_planner
    from emos.actors.nav.costmap.config import CostmapConfig
    from emos.actors.nav.costmap.filters import FilterMask, KeepoutFilter
    from emos.actors.nav.costmap.layered import LayeredCostmap
    from emos.actors.nav.costmap.zones import Zone, rasterize
    from emos.actors.nav.planning import OMPLConfig
    from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType

    house = _house()
    # The turtlebot-sized robot of the house recipes: a cylinder of 0.15 m radius.
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.15, 0.3]), ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
    rng = np.random.default_rng(seed)
    plain = make_global_planner(planner_id, robot, OMPLConfig(planning_timeout=2.0))
    plain.set_map(house)
    zoned = make_global_planner(planner_id, robot, OMPLConfig(planning_timeout=2.0))
    free = np.argwhere(house.data == 0)
    clear_of_walls = LayeredCostmap(CostmapConfig(enabled=True), robot.radius).set_map(house)
    rows = {"queries": 0, "entries": 0, "no_route": 0, "solved": 0, "skipped_no_base_route": 0}
    t_plain: list[float] = []
    t_zoned: list[float] = []
    t_layers: list[float] = []
    while rows["queries"] < queries:
        s, g = (np.r_[p, 0.0] for p in house.grid_to_world(free[rng.integers(len(free), size=2)][:, ::-1]))  # heading 0
        if np.hypot(*(g - s)[:2]) < 3.0 or np.any(clear_of_walls.cost_at(np.array([s[:2], g[:2]])) >= 128):
            continue
        t0 = time.perf_counter()
        base = plain.plan(s, g, timeout=2.0)
        t_plain.append(time.perf_counter() - t0)
        if not base.solved:
            rows["skipped_no_base_route"] += 1
            continue
        mid = base.path[len(base.path) // 2, :2]
        if min(np.hypot(*(mid - s[:2])), np.hypot(*(mid - g[:2]))) < 1.5 * zone_side:
            continue
        h = zone_side / 2
        zone = Zone(name=f"zone{rows['queries']}", kind="keepout",
                    polygon=((mid[0] - h, mid[1] - h), (mid[0] + h, mid[1] - h), (mid[0] + h, mid[1] + h), (mid[0] - h, mid[1] + h)))
        mask = house.copy_with(rasterize([zone], house.data.shape, house.resolution, house.origin, lambda z: 100).astype(np.int8))
        costmap = LayeredCostmap(CostmapConfig(enabled=True), robot.inner_radius)
        costmap.keepout = KeepoutFilter(FilterMask(path=Path(f"{zone.name}.yaml"), filter_type="keepout", grid=mask, zones=(zone,)))
        rows["queries"] += 1
        t0 = time.perf_counter()
        costmap.set_map(house)
        zoned.set_map(costmap.planning_grid(house))
        t1 = time.perf_counter()
        result = zoned.plan(s, g, timeout=2.0)
        t2 = time.perf_counter()
        t_layers.append(t1 - t0)
        t_zoned.append(t2 - t1)
        if not result.solved:
            rows["no_route"] += 1
            continue
        rows["solved"] += 1
        rows["entries"] += int(zone.contains(_dense(result.path)).any())

    def ms(values: list[float]) -> dict[str, float]:
        return {"median_ms": 1e3 * statistics.median(values), "p95_ms": 1e3 * float(np.percentile(values, 95))}

    return {"planner": planner_id, "seed": seed, "zone_m": zone_side, **rows,
            "plan_without_costmap": ms(t_plain), "plan_with_keepout": ms(t_zoned), "costmap_layers_update": ms(t_layers)}


def run(args: argparse.Namespace) -> int:
    if args.drive:
        from . import costmap_drive

        return costmap_drive.run(args)
    out = measure(args.queries, args.seed, args.planner, args.zone)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"keepout benchmark: house map, {out['queries']} queries (seed {out['seed']}), planner {out['planner']}, "
          f"zone {out['zone_m']} m square on the shortest route")
    print(f"  entries into keepout: {out['entries']}   solved: {out['solved']}   no route (zone closes it): {out['no_route']}")
    for key in ("plan_without_costmap", "plan_with_keepout", "costmap_layers_update"):
        print(f"  {key:24s} median {out[key]['median_ms']:8.1f} ms   p95 {out[key]['p95_ms']:8.1f} ms")
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    add_arguments(parser)
    raise SystemExit(run(parser.parse_args()))
