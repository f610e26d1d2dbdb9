"""``emos bench barn``: the BARN navigation benchmark in the simulator.

Runs the selected worlds under the challenge rules (start, goal, 1 m radius, 100 s limit,
collision = failure, official metric) with the Jackal-sized robot and its lidar, in lock-step
with the simulation clock, and prints a row per world and a summary (or JSON with ``--json``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .controllers import CONTROLLERS
from .harness import BarnRules, EpisodeResult, run_episode, score_run

__all__ = ["BarnRules", "EpisodeResult", "add_arguments", "run", "run_episode", "score_run", "summarize"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--worlds-file", type=Path, default=None,
                        help="BARN world file (default: ../shared/benchmarks/barn/worlds.json beside the repo)")
    parser.add_argument("--worlds", default=None, help="world indices, e.g. 1,2,5-9 (default: all in the file)")
    parser.add_argument("--controller", default="builtin", choices=sorted(CONTROLLERS),
                        help="navigation controller to drive with")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--png", type=Path, default=None, metavar="DIR", help="write each run's top-down picture here")
    parser.add_argument("--seed", type=int, default=0, help="simulation seed")
    parser.add_argument("--noisy-odometry", action="store_true",
                        help="navigate on drifting wheel odometry with 2%% slip instead of ground truth (harder)")


def summarize(results: list[EpisodeResult]) -> dict:
    n = len(results)
    if n == 0:
        return {"success_rate": 0.0, "collision_rate": 0.0, "timeout_rate": 0.0, "mean_metric": 0.0}
    return {
        "success_rate": round(sum(r.success for r in results) / n, 4),
        "collision_rate": round(sum(r.collided for r in results) / n, 4),
        "timeout_rate": round(sum(r.timeout for r in results) / n, 4),
        "mean_metric": round(sum(r.metric for r in results) / n, 4),
    }


def run(args: argparse.Namespace) -> int:
    from ..barn_worlds import load_barn_worlds, parse_indices
    from .controllers import make_controller

    try:
        worlds = load_barn_worlds(args.worlds_file)
        indices = parse_indices(args.worlds) if args.worlds else list(worlds)
    except (FileNotFoundError, ValueError) as exc:
        print(f"emos bench barn: {exc}", file=sys.stderr)
        return 2
    missing = [i for i in indices if i not in worlds]
    indices = [i for i in indices if i in worlds]
    if missing:
        # The shipped file holds 250 of 300 worlds (no multiples of 6): ranges skip the gaps.
        print(f"emos bench barn: skipping {len(missing)} world(s) not in the file: {missing}", file=sys.stderr)
    if not indices:
        print(f"emos bench barn: none of the selected worlds is in the file "
              f"({len(worlds)} worlds, {min(worlds)}..{max(worlds)})", file=sys.stderr)
        return 2
    rules = BarnRules(noisy_odometry=args.noisy_odometry)
    results: list[EpisodeResult] = []
    wall0 = time.perf_counter()
    if not args.json:
        print(f"BARN: {len(indices)} worlds, controller {args.controller}, lock-step sim clock")
        print(f"{'world':>5} {'result':<9} {'time_s':>7} {'metric':>7} {'dist_m':>7} {'wall_s':>7}  detail")
    for idx in indices:
        png = args.png / f"barn_{idx:03d}.png" if args.png else None
        navigator = make_controller(args.controller)
        r = run_episode(worlds[idx], navigator, rules, seed=args.seed, png_path=png)
        results.append(r)
        if not args.json:
            status = "success" if r.success else ("collision" if r.collided else "timeout")
            print(f"{r.idx:>5} {status:<9} {r.time_s:>7.2f} {r.metric:>7.3f} {r.distance_m:>7.2f} {r.wall_s:>7.2f}  {r.reason}",
                  flush=True)
    summary = summarize(results)
    if args.json:
        print(json.dumps({"worlds": [r.as_json() for r in results], "summary": summary}))
        return 0
    ok = [r for r in results if r.success]
    sim_total = sum(r.time_s for r in results)
    wall_total = time.perf_counter() - wall0
    print()
    print(f"worlds {len(results)}  success {summary['success_rate']:.3f}  collision {summary['collision_rate']:.3f}  "
          f"timeout {summary['timeout_rate']:.3f}  mean metric {summary['mean_metric']:.4f}")
    if ok:
        print(f"mean time of successful runs {sum(r.time_s for r in ok) / len(ok):.2f} s")
    print(f"simulated {sim_total:.1f} s in {wall_total:.1f} s wall ({sim_total / max(wall_total, 1e-9):.1f}x real time)")
    return 0
