"""``emos bench barn``: the BARN navigation benchmark in the simulator.

Runs the selected worlds under the challenge rules (start, goal, 1 m radius, 100 s limit,
collision = failure, official metric) with the Jackal-sized robot and its lidar, in lock-step
with the simulation clock, and prints a row per world and a summary (or JSON with ``--json``).

By default each world runs through the product: the Simulator and the navigation components
as supervised processes (:mod:`.stack`, :mod:`.process`), scored by a referee in the harness.
``--in-process`` drives a navigator object in this process instead (fast, for development).
Worlds come from ``--worlds-file``, else ``--barn-repo`` (a clone of the official repository,
all 300 worlds), else the 250 shipped in the package.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Callable

from .controllers import CONTROLLERS
from .harness import BarnRules, EpisodeResult, run_episode, score_run

__all__ = ["BarnRules", "EpisodeResult", "add_arguments", "run", "run_episode", "score_run", "summarize"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--worlds-file", type=Path, default=None,
                        help="BARN worlds JSON file (default: the 250 worlds shipped in the package)")
    parser.add_argument("--barn-repo", type=Path, default=None, metavar="PATH",
                        help="read world_<i>.world and path_files/path_<i>.npy from a clone of "
                             "github.com/Daffan/the-barn-challenge (all 300 worlds)")
    parser.add_argument("--worlds", default=None, help="world indices, e.g. 1,2,5-9 (default: all in the file)")
    parser.add_argument("--split", default="all", choices=SPLITS,
                        help="tune: worlds with idx %% 5 != 0 (for tuning); test: idx %% 5 == 0 (report only)")
    parser.add_argument("--in-process", action="store_true",
                        help="drive a navigator object in this process (fast path for development) instead of the "
                             "Simulator and navigation components as supervised processes")
    parser.add_argument("--controller", default="builtin", choices=sorted(CONTROLLERS),
                        help="navigation controller to drive with")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--png", type=Path, default=None, metavar="DIR", help="write each run's top-down picture here")
    parser.add_argument("--seed", type=int, default=0, help="simulation seed")
    parser.add_argument("--noisy-odometry", action="store_true",
                        help="navigate on drifting wheel odometry with 2%% slip instead of ground truth (harder)")


SPLITS = ("all", "tune", "test")


def in_split(idx: int, split: str) -> bool:
    """Tune on the worlds ``idx % 5 != 0``; report separately on ``idx % 5 == 0``."""
    return split == "all" or (idx % 5 == 0) == (split == "test")


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

    if args.worlds_file is not None and args.barn_repo is not None:
        print("emos bench barn: give --worlds-file or --barn-repo, not both", file=sys.stderr)
        return 2
    source = args.worlds_file if args.worlds_file is not None else args.barn_repo
    if not args.in_process and args.png is not None:
        print("emos bench barn: --png draws the in-process run; add --in-process", file=sys.stderr)
        return 2
    try:
        worlds = load_barn_worlds(source)
        indices = parse_indices(args.worlds) if args.worlds else list(worlds)
    except (FileNotFoundError, ValueError) as exc:
        print(f"emos bench barn: {exc}", file=sys.stderr)
        return 2
    missing = [i for i in indices if i not in worlds]
    indices = [i for i in indices if i in worlds and in_split(i, args.split)]
    if missing:
        # The shipped file holds 250 of 300 worlds (no multiples of 6): ranges skip the gaps.
        print(f"emos bench barn: skipping {len(missing)} world(s) not in the file: {missing}", file=sys.stderr)
    if not indices:
        print(f"emos bench barn: none of the selected worlds is in the file "
              f"({len(worlds)} worlds, {min(worlds)}..{max(worlds)}, split {args.split})", file=sys.stderr)
        return 2
    rules = BarnRules(noisy_odometry=args.noisy_odometry)
    if args.in_process:
        episode = _in_process_episode(worlds, rules, args)
        mode = ""  # the in-process output stays as it always was
    else:
        try:
            episode = _process_episode(worlds, rules, args, None if source is None else str(Path(source).resolve()))
        except ValueError as exc:
            print(f"emos bench barn: {exc}", file=sys.stderr)
            return 2
        mode = "supervised processes, "
    results: list[EpisodeResult] = []
    wall0 = time.perf_counter()
    if not args.json:
        print(f"BARN: {len(indices)} worlds, controller {args.controller}, {mode}lock-step sim clock")
        print(f"{'world':>5} {'result':<9} {'time_s':>7} {'metric':>7} {'dist_m':>7} {'wall_s':>7}  detail")
    for n, idx in enumerate(indices, 1):
        r = episode(idx)
        results.append(r)
        status = "success" if r.success else ("collision" if r.collided else "timeout")
        if not args.json:
            print(f"{r.idx:>5} {status:<9} {r.time_s:>7.2f} {r.metric:>7.3f} {r.distance_m:>7.2f} {r.wall_s:>7.2f}  {r.reason}",
                  flush=True)
        elif not args.in_process:  # slow enough to want a progress line; stdout stays pure JSON
            print(f"barn: world {idx} ({n}/{len(indices)}) {status} {r.time_s:.2f} s, {r.wall_s:.1f} s wall",
                  file=sys.stderr, flush=True)
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
    if args.split == "all":
        for split in ("tune", "test"):
            part = [r for r in results if in_split(r.idx, split)]
            if part and len(part) < len(results):
                s = summarize(part)
                print(f"  {split} worlds (idx % 5 {'!=' if split == 'tune' else '=='} 0): {len(part)}  "
                      f"success {s['success_rate']:.3f}  mean metric {s['mean_metric']:.4f}")
    if ok:
        print(f"mean time of successful runs {sum(r.time_s for r in ok) / len(ok):.2f} s")
    print(f"simulated {sim_total:.1f} s in {wall_total:.1f} s wall ({sim_total / max(wall_total, 1e-9):.1f}x real time)")
    return 0


def _in_process_episode(worlds: dict, rules: BarnRules, args: argparse.Namespace) -> Callable[[int], EpisodeResult]:
    from .controllers import make_controller

    def episode(idx: int) -> EpisodeResult:
        png = args.png / f"barn_{idx:03d}.png" if args.png else None
        return run_episode(worlds[idx], make_controller(args.controller), rules, seed=args.seed, png_path=png)

    return episode


def _process_episode(worlds: dict, rules: BarnRules, args: argparse.Namespace,
                     source: str | None) -> Callable[[int], EpisodeResult]:
    from .process import SystemFailed, run_episode_process
    from .stack import StackOptions

    StackOptions.for_controller(args.controller, world=min(worlds))  # an unsupported controller fails here

    def episode(idx: int) -> EpisodeResult:
        opts = StackOptions.for_controller(args.controller, world=idx, rules=rules, barn_source=source, seed=args.seed)
        try:
            return run_episode_process(worlds[idx], opts)
        except SystemFailed as exc:
            # One broken world must not end a 250-world run: it counts as a failure, loudly.
            print(f"emos bench barn: world {idx}: system failure: {exc}", file=sys.stderr, flush=True)
            return EpisodeResult(idx, False, False, True, 0.0, 0.0, reason="system failure (see stderr)")

    return episode
