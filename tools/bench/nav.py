"""``emos bench nav``: timings of the navigation kernels, plus part A's planner table.

Measured (all CPU, numpy, the process's threads):

* ``cost_eval_ms``: the four path costs (reference path, goal, smoothness, jerk) of 5,001
  trajectories x 1,000 points against a 1,000-point reference path (includes building the
  nearest-segment field for that path).
* ``local_map_ms``: 3,600 beams of range ``5 + 2 sin(20 theta)`` into a 400 x 400 grid at
  0.05 m (steady state: the per-cell beam lookup for a scan layout is built once).
* ``critical_zone_100k_ms`` / ``critical_zone_scan_ms``: the critical/slowdown zone check over
  100,000 cloud points and over a 3,600-beam scan.
* ``dwa_step_ms``: full DWA steps (20 x 20 samples, 10-step horizon, 720-beam scan) along a
  closed-loop run past obstacles; p50 and p95.
* ``planning``: rows of ``emos.tools.bench.nav_planning.run_planning_table`` (1 s budget).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

from emos.actors.nav.controllers.dwa import DWA, DWAConfig
from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.costs import TrajectoryCostsWeights, evaluate_costs, polyline_distance_exact
from emos.actors.nav.kinematics import integrate, rollout
from emos.actors.nav.local_map import LocalMapper, MapConfig
from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig
from emos.actors.nav.safety import SafetyZones, SafetyZonesConfig, SweptFootprint

__all__ = ["add_arguments", "run", "measure_kernels"]


def _median_ms(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def _robot() -> RobotConfig:
    return RobotConfig(
        model_type="DIFFERENTIAL_DRIVE", geometry_type="CYLINDER", geometry_params=np.array([0.2, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.0, max_decel=2.0),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))


def _cost_problem() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """(trajectories, velocities, reference path, commands, dt) of the cost benchmark."""
    rng = np.random.default_rng(0)
    n_traj, n_pts, dt = 5001, 1000, 0.01
    s = np.linspace(0.0, 12.0, 1000)
    reference = np.stack([s, 1.5 * np.sin(s / 2.0)], axis=1)
    commands = np.stack([rng.uniform(0.2, 1.0, n_traj), np.zeros(n_traj), rng.uniform(-1.0, 1.0, n_traj)], 1)
    trajectories = rollout(np.zeros(3), commands, dt, n_pts - 1).astype(np.float32)
    # Velocity profiles that change along the trajectory, so smoothness and jerk do work.
    ramp = np.linspace(0.5, 1.0, n_pts, dtype=np.float32)[None, :, None]
    velocities = (commands.astype(np.float32)[:, None, :] * ramp).astype(np.float32)
    return trajectories, velocities, reference, commands, dt


def bench_dense_reference_path(trajectories: np.ndarray, reference: np.ndarray, sample: int = 50) -> float:
    """Same-run peer: exact point-to-polyline distances for 1/``sample`` of the trajectories
    (all 999 segments, no field), scaled to the full set (ms)."""
    subset = trajectories[::sample, :, :2]
    t0 = time.perf_counter()
    polyline_distance_exact(subset, reference).mean(axis=1)
    return 1e3 * (time.perf_counter() - t0) * trajectories.shape[0] / subset.shape[0]


def bench_cost_eval(repeats: int = 5) -> float:
    trajectories, velocities, reference, _, dt = _cost_problem()
    weights = TrajectoryCostsWeights(reference_path_distance_weight=1.0, goal_distance_weight=1.0,
                                     obstacles_distance_weight=0.0, smoothness_weight=1.0, jerk_weight=1.0)

    def once() -> None:
        evaluate_costs(weights, trajectories, velocities, reference_path=reference, goal=reference[-1],
                       dt=dt, acc_limits=np.array([1.0, 1.0, 2.0]))

    return _median_ms(once, repeats)


def _bench_scan(n: int = 3600) -> LaserScan2D:
    theta = -math.pi + np.arange(n) * (2 * math.pi / n)
    return LaserScan2D(5.0 + 2.0 * np.sin(20.0 * theta), angle_min=-math.pi,
                       angle_increment=2 * math.pi / n, range_max=10.0)


def bench_local_map(repeats: int = 50) -> tuple[float, float, float]:
    """(steady-state ms, first-update ms including the per-layout cell/beam table, and the
    same-run peer: ms of the direct ray-sampling tracer on the same scan)."""
    scan = _bench_scan()
    mapper = LocalMapper(MapConfig(width=20.0, height=20.0, resolution=0.05))
    t0 = time.perf_counter()
    mapper.update(scan)
    cold = 1e3 * (time.perf_counter() - t0)
    steady = _median_ms(lambda: mapper.update(scan), repeats, warmup=0)
    rays = _median_ms(lambda: mapper.trace_rays(scan), max(5, repeats // 10))
    return steady, cold, rays


def bench_critical_zone(repeats: int = 200) -> tuple[float, float]:
    robot = _robot()
    zones = SafetyZones(robot, SafetyZonesConfig(critical_zone_distance=0.1, slowdown_zone_distance=0.3,
                                                 critical_zone_angle=90.0))
    cloud = np.random.default_rng(1).uniform([-5, -5, 0], [5, 5, 1], (100_000, 3)).astype(np.float32)
    scan = _bench_scan()
    cloud_ms = _median_ms(lambda: zones.check_points(cloud), max(20, repeats // 4))
    scan_ms = _median_ms(lambda: zones.check_scan(scan), repeats * 5)
    return cloud_ms, scan_ms


def _circle_scan(pose: np.ndarray, circles: list[tuple[float, float, float]], n: int = 720) -> LaserScan2D:
    ang = -math.pi + np.arange(n) * (2 * math.pi / n)
    dirs = np.stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])], 1)
    ranges = np.full(n, np.inf)
    for cx, cy, r in circles:
        oc = np.array([pose[0] - cx, pose[1] - cy])
        b = dirs @ oc
        disc = b * b - (oc @ oc - r * r)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        ranges = np.minimum(ranges, np.where((disc >= 0) & (t > 0), t, np.inf))
    ranges[ranges > 8.0] = np.inf
    return LaserScan2D(ranges, angle_min=-math.pi, angle_increment=2 * math.pi / n, range_max=8.0)


def bench_swept(commands: int = 500, native: bool | None = None) -> dict[str, Any]:
    """The DriveManager's swept-footprint check, one call per command: the realistic Jackal
    (jackal-barn box, its limits, the default skid-steer motion model) among BARN-like posts
    (radius 0.075 m, one per 0.6 m^2 on average, none inside the robot), commands and previous
    commands drawn over its speed range. Time per call (ms), the points prepared once as the
    DriveManager prepares them once per scan (``prepare_ms``: that per-scan work, once).
    ``history_cpu_p50`` / ``history_cpu_p99``: the thread CPU of one more call per command with
    a history of sent commands as the DriveManager passes one (the last 0.25 s at 20 Hz, near
    the previous command), the path it takes in a running system. ``native``: SweptFootprint's
    (None: the C inner loop if it was built, what users get; False: numpy alone); ``native`` in
    the result says which ran."""
    from emos.actors.sim.robots import PRESETS
    from emos.tools.barn.harness import nav_robot

    rng = np.random.default_rng(38)
    robot = nav_robot(PRESETS["jackal-barn"])
    swept = SweptFootprint(robot, native=native)
    xy = rng.uniform(-3.0, 3.0, (60, 2))
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) > robot.radius + 0.2]
    scan = _circle_scan(np.zeros(3), [(float(x), float(y), 0.075) for x, y in xy])
    points = scan.points()
    c0 = time.thread_time()
    prepared = swept.prepare(points)
    prepare_ms = 1e3 * (time.thread_time() - c0)
    cmds = np.c_[rng.uniform(-0.5, 2.0, commands), np.zeros(commands), rng.uniform(-3.0, 3.0, commands)]
    prevs = np.clip(cmds + np.c_[rng.normal(0, 0.2, commands), np.zeros(commands), rng.normal(0, 0.3, commands)], -3, 3)
    # Per command: the fastest of three calls (what it costs on a core of its own: the others
    # are another process's turn on this shared machine) and the first call as it came.
    # The thread's CPU time too: what the call costs whoever else runs.
    best, first, cpu, stopped = [], [], [], 0
    for cmd, prev in zip(cmds, prevs):
        times = []
        for _ in range(3):
            c0, t0 = time.thread_time(), time.perf_counter()
            result = swept.check(cmd, prev, prepared, lead=0.02)
            times.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
        best.append(min(times))
        first.append(times[0])
        stopped += result.stopped
    sent_at = -0.05 * np.arange(6)[::-1]
    with_history = []
    for cmd, prev in zip(cmds, prevs):
        history = (sent_at, prev + rng.normal(0.0, 0.1, (6, 3)) * [1.0, 0.0, 1.0])
        c0 = time.thread_time()
        swept.check(cmd, prev, prepared, lead=0.02, history=history)
        with_history.append(time.thread_time() - c0)
    b, f, c, h = 1e3 * np.asarray(best), 1e3 * np.asarray(first), 1e3 * np.asarray(cpu), 1e3 * np.asarray(with_history)
    return {"p50": float(np.percentile(b, 50)), "p99": float(np.percentile(b, 99)), "max": float(b.max()),
            "first_p99": float(np.percentile(f, 99)), "cpu_p50": float(np.percentile(c, 50)),
            "cpu_p99": float(np.percentile(c, 99)), "points": int(len(points)), "stopped": stopped / commands,
            "prepare_ms": prepare_ms, "history_cpu_p50": float(np.percentile(h, 50)),
            "history_cpu_p99": float(np.percentile(h, 99)), "native": swept._native is not None}


def bench_dwa(steps: int = 200) -> dict[str, float]:
    robot = _robot()
    dwa = DWA(robot, DWAConfig(control_time_step=0.1, prediction_horizon=1.0, control_horizon=0.2,
                               max_linear_samples=20, max_angular_samples=20))
    x = np.linspace(0.0, 8.0, 161)
    dwa.set_path(np.stack([x, 0.3 * np.sin(x)], 1))
    circles = [(2.5, 0.3, 0.2), (5.0, -0.8, 0.3), (6.0, 1.0, 0.25)] + [(xx, 2.0, 0.1) for xx in np.arange(0, 8, 0.5)]
    pose, vel = np.zeros(3), np.zeros(3)
    times = []
    for _ in range(steps):
        scan = _circle_scan(pose, circles)
        t0 = time.perf_counter()
        res = dwa.compute(pose, vel, scan)
        times.append(time.perf_counter() - t0)
        if res.status.value == "goal_reached":
            dwa.set_path(np.stack([x, 0.3 * np.sin(x)], 1))
            pose, vel = np.zeros(3), np.zeros(3)
            continue
        vel = res.command
        pose = integrate(pose, vel, 0.1)
    arr = 1e3 * np.asarray(times)
    return {"p50": float(np.percentile(arr, 50)), "p95": float(np.percentile(arr, 95))}


def bench_mppi(steps: int = 60) -> dict[str, Any]:
    """MPPI with Nav2's example batch (2,000 samples x 56 steps of 0.05 s) on DWA's course, one
    thread: time per control step, the rate it allows, and where the time goes (per stage)."""
    from emos.actors.nav.controllers.mppi import MPPI, MPPIConfig

    robot = _robot()
    mppi = MPPI(robot, MPPIConfig(batch_size=2000, time_steps=56, model_dt=0.05, control_time_step=0.1))
    x = np.linspace(0.0, 8.0, 161)
    mppi.set_path(np.stack([x, 0.3 * np.sin(x)], 1))
    circles = [(2.5, 0.3, 0.2), (5.0, -0.8, 0.3), (6.0, 1.0, 0.25)] + [(xx, 2.0, 0.1) for xx in np.arange(0, 8, 0.5)]
    pose, vel = np.zeros(3), np.zeros(3)
    times, cpu = [], []
    mppi.compute(pose, vel, _circle_scan(pose, circles))  # first step: imports and allocations
    mppi.stage_ms = {}
    for _ in range(steps):
        scan = _circle_scan(pose, circles)
        t0, c0 = time.perf_counter(), time.thread_time()
        res = mppi.compute(pose, vel, scan)
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
        if res.status.value == "goal_reached":
            mppi.set_path(np.stack([x, 0.3 * np.sin(x)], 1))
            pose, vel = np.zeros(3), np.zeros(3)
            continue
        vel = res.command
        pose = integrate(pose, vel, 0.1)
    arr, cpu_ms = 1e3 * np.asarray(times), 1e3 * np.asarray(cpu)
    p50 = float(np.percentile(arr, 50))
    # CPU time says what one core costs when the machine is shared (the wall clock then counts
    # other processes' turns too); the stages are the thread's CPU time per step.
    return {"p50": p50, "p95": float(np.percentile(arr, 95)), "hz_at_p50": 1e3 / p50,
            "cpu_p50": float(np.percentile(cpu_ms, 50)), "hz_at_cpu_p50": 1e3 / float(np.percentile(cpu_ms, 50)),
            "stages_ms": {k: round(v / steps, 3) for k, v in mppi.stage_ms.items()}}


def measure_kernels(peers: bool = False) -> dict[str, Any]:
    """The JSON kernels; with ``peers`` also the same-run reference formulations."""
    local_ms, local_cold, local_rays = bench_local_map()
    dense = swept_numpy = None
    if peers:
        trajectories, _, reference, _, _ = _cost_problem()
        dense = bench_dense_reference_path(trajectories, reference)
        swept_numpy = bench_swept(native=False)
    cloud_ms, scan_ms = bench_critical_zone()
    return {
        "cost_eval_ms": bench_cost_eval(),
        "local_map_ms": local_ms,
        "critical_zone_100k_ms": cloud_ms,
        "critical_zone_scan_ms": scan_ms,
        "dwa_step_ms": bench_dwa(),
        "mppi_step_ms": bench_mppi(),
        "swept_check_ms": bench_swept(),
        "_local_map_cold_ms": local_cold,
        "_local_map_rays_ms": local_rays,
        "_dense_cost_ms": dense,
        "_swept_numpy_ms": swept_numpy,
    }


def _planning(budget: float, planners: list[str] | None) -> tuple[list[dict[str, Any]], str | None]:
    try:
        from .nav_planning import run_planning_table
    except Exception as exc:  # part A's module missing or broken: report, never fake rows
        return [], f"planning table unavailable: {type(exc).__name__}: {exc}"
    try:
        return run_planning_table(budget_s=budget, planners=planners), None
    except Exception as exc:
        return [], "planning table failed: " + "".join(traceback.format_exception_only(type(exc), exc)).strip()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--planning-budget", type=float, default=1.0, help="seconds per planner (default 1.0)")
    parser.add_argument("--planners", nargs="*", default=None, help="planner ids (default: every available one)")


def _fmt(v: Any) -> str:
    return "-" if v is None else (f"{v:.4g}" if isinstance(v, float) else str(v))


def run(args: argparse.Namespace) -> int:
    kernels = measure_kernels(peers=not args.json)
    rows, error = _planning(args.planning_budget, args.planners)
    result = {k: v for k, v in kernels.items() if not k.startswith("_")}
    result["planning"] = rows
    if args.json:
        print(json.dumps(result))
        return 0 if error is None else 1
    targets = {"cost_eval_ms": 500.0, "local_map_ms": 10.0, "critical_zone_100k_ms": 2.0,
               "critical_zone_scan_ms": 0.1}
    print("Navigation kernels (CPU, numpy; the machine's 2 cores are shared with other work)")
    print(f"{'kernel':<26}{'ms':>10}{'target ms':>12}")
    for key, target in targets.items():
        print(f"{key:<26}{result[key]:>10.3f}{target:>12.1f}")
    print(f"{'local_map (first scan)':<26}{kernels['_local_map_cold_ms']:>10.3f}{'':>12}")
    dwa = result["dwa_step_ms"]
    print(f"{'dwa_step p50 / p95':<26}{dwa['p50']:>10.3f}{10.0:>12.1f}   p95 {dwa['p95']:.3f}")
    mp = result["mppi_step_ms"]
    print(f"{'mppi_step p50 / p95':<26}{mp['p50']:>10.3f}{33.3:>12.1f}   p95 {mp['p95']:.3f}  ({mp['hz_at_p50']:.0f} Hz; thread CPU "
          f"p50 {mp['cpu_p50']:.1f} ms = {mp['hz_at_cpu_p50']:.0f} Hz; 2,000 x 56, "
          "per stage: " + ", ".join(f"{k} {v:.1f}" for k, v in mp["stages_ms"].items()) + ")")
    sw = result["swept_check_ms"]
    print(f"{'swept_check p50 / p99':<26}{sw['p50']:>10.3f}{1.0:>12.1f}   p99 {sw['p99']:.3f} (best of 3 per command; "
          f"first call p99 {sw['first_p99']:.3f}; thread CPU p50 {sw['cpu_p50']:.3f}, p99 {sw['cpu_p99']:.3f}); "
          f"{sw['points']} scan points, {100 * sw['stopped']:.0f}% of commands stopped; "
          f"with a history (the DriveManager's path): thread CPU p50 {sw['history_cpu_p50']:.3f}, p99 {sw['history_cpu_p99']:.3f}")
    print("Same-run peers (direct formulations of the same computation):")
    rays = kernels["_local_map_rays_ms"]
    print(f"  local map by sampling every ray: {rays:.3f} ms ({rays / result['local_map_ms']:.1f}x the cell lookup)")
    numpy_swept = kernels["_swept_numpy_ms"]
    if sw["native"]:
        print(f"  swept check in numpy alone (the install without a C compiler): p50 {numpy_swept['p50']:.3f}, "
              f"p99 {numpy_swept['p99']:.3f} ms, thread CPU p99 {numpy_swept['cpu_p99']:.3f} "
              f"({numpy_swept['p99'] / sw['p99']:.1f}x the C inner loop's p99)")
    dense = kernels["_dense_cost_ms"]
    print(f"  reference-path distance, exact against all 999 segments (1/50 of the trajectories, "
          f"scaled): {dense:.0f} ms ({dense / result['cost_eval_ms']:.0f}x the whole cost evaluation)")
    print()
    if error:
        print(error)
    else:
        print("Planning (each planner, 1 query on the rooms map)")
        print(f"{'planner':<18}{'solved':>8}{'time_s':>10}{'length_m':>10}{'simplify_s':>12}")
        for row in rows:
            print(f"{row['planner']:<18}{str(row['solved']):>8}{_fmt(row.get('time_s')):>10}"
                  f"{_fmt(row.get('length_m')):>10}{_fmt(row.get('simplification_time_s')):>12}")
    return 0 if error is None else 1
