"""Keepout zones while driving (``emos bench costmap --drive N``): seeded missions in the simulated
house, driven by the point-navigation stack in its own processes, with a keepout zone on the
shortest route of each leg. The referee is the Simulator's ground truth: an *entry* is any moment
the robot's footprint reaches more than ``ENTRY_DEPTH`` into a zone (goal: 0).

``--scope stack`` (the default): ``NavigationStack.use_zones`` (the Planner plans round the zones,
the Controller and the DriveManager keep out of them). ``--scope local``: the Planner is not told
(its plans cross the zones, as a path from another planner or a person would), so only the
Controller's and the DriveManager's keepout stand between the robot and the zones; legs whose
only way is through a zone then end at their time limit, which is expected, not a failure.

The recovery ladder of the patrol (clear the local grid, back up, spin) runs on the Controller's
failures, so recoveries near zones are part of what is measured. The missions: goals drawn from
the free space at least 3 m apart, seeded; each leg's zone is a square of ``--zone`` m centred on
the middle of the route planned without zones (or a little before or after it), kept only where
every leg keeps a route round all the zones (for a robot 0.1 m wider) and clear of every goal and
of the spawn.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["measure", "plan_missions"]

ENTRY_DEPTH = 0.01  # m of footprint inside a zone that count as an entry (ground truth is exact; cells are 5 cm)
ROBOT_RADIUS = 0.2  # the patrol's robot
SPAWN = (1.5, 1.5)
LEG_TIMEOUT = 90.0  # simulated s per leg
REACHED = 0.35  # m from the goal (the Controller's tolerance plus its stop)

RECIPE = """
import numpy as np
from emos import Action, Launcher, Topic
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components.behaviors import BehaviorsConfig
from emos.actors.nav.stacks import COMMAND_INPUTS, point_navigation_stack
from emos.actors.sim import Simulator, SimulatorConfig

robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.2, 0.3]))
odom = Topic(name="/odom", msg_type="Odometry")
scan = Topic(name="/scan", msg_type="LaserScan")
sim = Simulator("sim", config=SimulatorConfig(world="house"))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom, scan=scan)
stack = point_navigation_stack(robot, RobotFrames(world="map", odom="map", scan="LDS-01"), HOUSE_MAP, odom=odom,
                               command=Topic(name="/cmd_vel", msg_type="Twist"), scan=scan, command_inputs=COMMAND_INPUTS)
if SCOPE == "stack":
    stack.use_zones(keepout_mask=MASK)
else:
    stack.controller.config.keepout_mask = MASK
    stack.driver.config.keepout_mask = MASK
behaviors = stack.behaviors(config=BehaviorsConfig(local_mapper=stack.local_mapper.component_name, max_rotational_vel=1.0))
stack.controller.on_algorithm_fail(action=[Action(method=behaviors.clear_costmaps), Action(method=behaviors.back_up),
                                           Action(method=behaviors.spin)], max_retries=3)
launcher = Launcher(heartbeat_timeout=15.0)
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
stack.launch(launcher)
launcher.add_pkg(components=[behaviors], package_name="recovery", multiprocessing=True)
stack.controller.config.fallback_rate = 1 / 4
launcher.bringup()
"""
COMPONENTS = ("sim", "planner", "controller", "drive_manager", "mapper", "behaviors")


def _house() -> Any:
    import emos.actors.sim.data as data
    from emos.actors.nav.maps import load_map

    return load_map(os.path.join(os.path.dirname(data.__file__), "house.yaml"))


def _square(name: str, centre: np.ndarray, side: float, grid: Any) -> Any:
    """A square zone round ``centre`` with its sides on cell boundaries of ``grid`` (the mask's
    cells then cover the square exactly: an entry is the robot's, not the rasterization's)."""
    from emos.actors.nav.costmap.zones import Zone

    res, ox, oy = grid.resolution, grid.origin[0], grid.origin[1]
    x0 = ox + round((float(centre[0]) - side / 2 - ox) / res) * res
    y0 = oy + round((float(centre[1]) - side / 2 - oy) / res) * res
    x1, y1 = x0 + round(side / res) * res, y0 + round(side / res) * res
    return Zone(name=name, kind="keepout", polygon=((x0, y0), (x1, y0), (x1, y1), (x0, y1)))


def _depth(xy: np.ndarray, zone: Any, radius: float) -> float:
    """How far a disc of ``radius`` at ``xy`` reaches into the square ``zone`` (<= 0: it does not)."""
    (x0, y0), _, (x1, y1), _ = zone.polygon
    dx = max(x0 - xy[0], 0.0, xy[0] - x1)
    dy = max(y0 - xy[1], 0.0, xy[1] - y1)
    if dx or dy:
        return radius - math.hypot(dx, dy)
    return radius + min(xy[0] - x0, x1 - xy[0], xy[1] - y0, y1 - xy[1])


def plan_missions(legs: int, seed: int, zone_side: float) -> tuple[list[tuple[float, float]], list[Any], int]:
    """(goals, zones, legs whose zone was dropped): ``legs`` goals from the spawn, seeded, and the
    zone of each leg that keeps a route round it."""
    from emos.actors.nav.components.planners import make_global_planner
    from emos.actors.nav.costmap.config import CostmapConfig
    from emos.actors.nav.costmap.layered import LayeredCostmap
    from emos.actors.nav.costmap.zones import rasterize
    from emos.actors.nav.planning import OMPLConfig
    from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType

    house = _house()
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    rng = np.random.default_rng(seed)
    planner = make_global_planner("CostToGo", robot, OMPLConfig(planning_timeout=2.0))
    planner.set_map(house)
    # The way round a zone is judged for a robot 0.1 m wider than this one: the grid planner's
    # clearance is its cells', and a way the stack's planner and controller find only on paper
    # would measure the zone's placement, not the keepout.
    wider = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS + 0.1, 0.3]))
    zoned = make_global_planner("CostToGo", wider, OMPLConfig(planning_timeout=2.0))
    clear_of_walls = LayeredCostmap(CostmapConfig(enabled=True), ROBOT_RADIUS).set_map(house)
    free = house.grid_to_world(np.argwhere(house.data == 0)[:, ::-1])
    free = free[clear_of_walls.cost_at(free) < 64]  # room to stand and turn
    goals: list[tuple[float, float]] = []
    zones: list[Any] = []
    dropped = 0
    legs_so_far: list[tuple[np.ndarray, np.ndarray]] = []
    here = np.array(SPAWN)
    while len(goals) < legs:
        goal = free[rng.integers(len(free))]
        if np.hypot(*(goal - here)) < 3.0 or any(_depth(goal, z, ROBOT_RADIUS + 0.3) > 0 for z in zones):
            continue
        base = planner.plan(np.r_[here, 0.0], np.r_[goal, 0.0], timeout=2.0)
        if not base.solved:
            continue
        path = base.path[:, :2]
        s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))]
        # The middle of the route first; where a zone there leaves no way round (a doorway), a
        # little before or after it.
        for share in (0.5, 0.4, 0.6, 0.3, 0.7):
            zone = _square(f"leg{len(goals) + 1}", path[int(np.searchsorted(s, share * s[-1]))], zone_side, house)
            if any(_depth(p, zone, ROBOT_RADIUS + 0.3) > 0 for p in [here, goal, np.array(SPAWN), *map(np.array, goals)]):
                continue
            cells = rasterize([*zones, zone], house.data.shape, house.resolution, house.origin, lambda z: 100) >= 100
            zoned.set_map(house.copy_with(np.where(cells, np.int8(100), house.data).astype(np.int8)))
            # Every leg so far keeps a way round too: all the zones are in the mask at once.
            if all(zoned.plan(np.r_[a, 0.0], np.r_[b, 0.0], timeout=2.0).solved for a, b in [*legs_so_far, (here, goal)]):
                zones.append(zone)
                break
        else:
            dropped += 1
        goals.append((float(goal[0]), float(goal[1])))
        legs_so_far.append((here, goal))
        here = goal
    return goals, zones, dropped


def measure(legs: int = 20, seed: int = 0, zone_side: float = 0.6, scope: str = "stack",
            progress: Any = None) -> dict[str, Any]:
    """Drive the missions through the processes; the result (see the module doc)."""
    from emos import msgs as M
    from emos.actors.nav.costmap.mask_io import write_mask
    from emos.core import control as C
    from emos.core.rpc import RpcClient
    from emos.supervisor.launched import wait_active, wait_run_dir
    from emos.transport.context import RunContext
    from emos.transport.pubsub import Publisher

    if scope not in ("stack", "local"):
        raise ValueError(f"bench costmap --drive: --scope must be 'stack' or 'local', got {scope!r}")
    if legs < 1:
        raise ValueError(f"bench costmap --drive: expected at least 1 leg, got {legs}")
    say = progress or (lambda line: None)
    goals, zones, dropped = plan_missions(legs, seed, zone_side)
    import emos.actors.sim.data as data

    with tempfile.TemporaryDirectory(prefix="emos-bench-keepout-") as tmp:
        mask = write_mask(Path(tmp) / "keepout.yaml", zones, "keepout", _house())
        script = Path(tmp) / "recipe.py"
        script.write_text(f"HOUSE_MAP = {os.path.join(os.path.dirname(data.__file__), 'house.yaml')!r}\n"
                          f"MASK = {str(mask)!r}\nSCOPE = {scope!r}\n" + RECIPE)
        log_path = Path(tmp) / "system.log"
        with open(log_path, "wb") as log:
            proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(script)], stdout=log, stderr=subprocess.STDOUT, cwd=tmp)
        results: list[dict[str, Any]] = []
        goal_pub = None
        try:
            run_dir = wait_run_dir(proc, log_path, "bench costmap --drive")
            ctx = RunContext(run_dir.name, run_dir, owner=False)
            rpc = RpcClient(run_dir / "supervisor.sock")
            wait_active(rpc, proc, log_path, COMPONENTS, "bench costmap --drive", timeout=180.0)
            rpc.close()
            sim = C.ControlClient("sim", ctx, timeout=10.0)
            goal_pub = Publisher(ctx, "/goal", M.PointStamped, publisher_id="bench_keepout_goal")
            for i, goal in enumerate(goals):
                results.append(_drive_leg(sim, goal_pub, goal, zones, proc))
                r = results[-1]
                near = f"{r['depth_m']:.3f} m into a zone" if r["depth_m"] > 0 else f"least gap to a zone {-r['depth_m']:.2f} m"
                say(f"leg {i + 1}/{len(goals)}: {'reached' if r['reached'] else 'not reached'} in {r['sim_s']:.0f} s, {near}")
                if proc.poll() is not None:
                    raise RuntimeError(f"bench costmap --drive: the system ended (exit {proc.returncode}); log:\n"
                                       f"{log_path.read_text()[-3000:]}")
        finally:
            if goal_pub is not None:
                goal_pub.close()
            proc.terminate()
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    entries = [r for r in results if r["depth_m"] > ENTRY_DEPTH]
    return {"scope": scope, "seed": seed, "zone_m": zone_side, "legs": len(results), "zones": len(zones),
            "zones_dropped": dropped, "entries": len(entries), "deepest_m": round(max((r["depth_m"] for r in results), default=0.0), 4),
            "reached": sum(r["reached"] for r in results), "sim_s": round(sum(r["sim_s"] for r in results), 1),
            "least_gap_m": round(-max((r["depth_m"] for r in results), default=-math.inf), 4), "per_leg": results}


def _drive_leg(sim: Any, goal_pub: Any, goal: tuple[float, float], zones: list[Any], proc: subprocess.Popen) -> dict[str, Any]:
    """Send ``goal`` (again every 2 s) until the robot is within ``REACHED`` of it, standing, or
    ``LEG_TIMEOUT`` simulated seconds passed; the deepest reach of the footprint into any zone."""
    from emos import msgs as M

    start: float | None = None
    depth, sent_at, reached, t = -math.inf, -math.inf, False, 0.0
    while proc.poll() is None:
        try:
            st = sim.execute_method("sim_status")
        except Exception:  # noqa: BLE001 - a busy simulator: ask again
            time.sleep(0.1)
            continue
        if "pose" not in st:
            time.sleep(0.1)
            continue
        t = float(st["sim_time"])
        start = t if start is None else start
        xy = np.array(st["pose"][:2])
        depth = max([depth, *(_depth(xy, z, ROBOT_RADIUS) for z in zones)])
        if np.hypot(*(xy - goal)) <= REACHED:
            reached = True
            break
        if t - start > LEG_TIMEOUT:
            break
        if time.monotonic() - sent_at >= 2.0:
            goal_pub.publish(M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=goal[0], y=goal[1])))
            sent_at = time.monotonic()
        time.sleep(0.05)
    return {"goal": [round(goal[0], 2), round(goal[1], 2)], "reached": reached, "sim_s": round(t - (start or t), 1),
            "depth_m": round(depth, 4)}


def run(args: argparse.Namespace) -> int:
    # Progress on stderr with --json: the result alone on stdout.
    out = measure(args.drive, args.seed, args.zone, args.scope,
                  progress=lambda line: print(line, file=sys.stderr if args.json else sys.stdout, flush=True))
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"keepout while driving: house, {out['legs']} legs (seed {out['seed']}), {out['zones']} zones of {out['zone_m']} m "
          f"on the shortest routes ({out['zones_dropped']} dropped: no way round), scope {out['scope']}")
    print(f"  entries (footprint > {ENTRY_DEPTH} m into a zone): {out['entries']}   least gap to a zone {out['least_gap_m']:.3f} m   "
          f"reached {out['reached']}/{out['legs']}   {out['sim_s']:.0f} simulated s")
    return 0
