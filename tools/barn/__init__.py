"""``emos bench barn``: the BARN navigation benchmark in the simulator.

Runs the selected worlds under the challenge rules (start, goal, 1 m radius, 100 s on the
official clock that starts after 0.1 m of motion, collision = failure, official metric), each
with ``--seeds`` seeds (different sensor noise, odometry errors and yaw gain), in lock-step
with the simulation clock, and prints a row per world and the summary over all trials (or
JSON with ``--json``).

Realistic by default: the ``jackal-barn`` robot (calibrated skid-steer drive, official
collision shape), the Jackal laser, wheel + IMU odometry, the navigator's compute time
charged. ``--ideal``: the kinematic robot with ground-truth odometry of the first benchmark.
``--robot jackal-wheeled``: pybullet wheels. ``--dynabarn``: the moving-obstacle set.

Through the product by default: each trial runs the Simulator and the navigation components
as supervised processes (:mod:`.stack`, :mod:`.process`), scored by a referee in the harness
that alone reads the ground truth. ``--in-process`` drives a navigator object in this process
instead (the fast path for development). BARN worlds come from ``--worlds-file``, else
``--barn-repo`` (a clone of the official repository: all 300 worlds), else the 250 shipped in
the package.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import attrs

from .controllers import CONTROLLERS
from .harness import BarnRules, EpisodeResult, run_episode, score_run

DEFAULT_CONTROLLER = "builtin-robust"  # plans with the turn the base achieves: the realistic robot is the default
DYNABARN_DEFAULT_CONTROLLER = "builtin-dynamic"  # the moving-obstacle set needs the navigator that tracks movers

__all__ = ["BarnRules", "EpisodeResult", "add_arguments", "run", "run_episode", "score_run", "summarize"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--worlds-file", type=Path, default=None,
                        help="world file (default: the 250 BARN worlds shipped in the package; "
                             "with --dynabarn the shipped moving-obstacle set)")
    parser.add_argument("--barn-repo", type=Path, default=None, metavar="PATH",
                        help="read world_<i>.world and path_files/path_<i>.npy from a clone of "
                             "github.com/Daffan/the-barn-challenge (all 300 worlds)")
    parser.add_argument("--in-process", action="store_true",
                        help="drive a navigator object in this process (the fast path for development) instead of "
                             "the Simulator and the navigation components as supervised processes")
    parser.add_argument("--worlds", default=None, help="world indices, e.g. 1,2,5-9 (default: all in the file)")
    parser.add_argument("--split", default="all", choices=("all", "tune", "test"),
                        help="tune: worlds with idx %% 5 != 0 (for tuning); test: idx %% 5 == 0 (report only)")
    parser.add_argument("--controller", default=None, choices=sorted(CONTROLLERS),
                        help=f"navigation controller to drive with (default: {DEFAULT_CONTROLLER}; with --dynabarn "
                             f"{DYNABARN_DEFAULT_CONTROLLER})")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--png", type=Path, default=None, metavar="DIR", help="write each run's top-down picture here")
    parser.add_argument("--seeds", type=int, default=10, help="trials per world, each with its own noise and yaw gain "
                                                              "(default 10)")
    parser.add_argument("--seed", type=int, default=0, help="base of the trial seeds (default 0)")
    parser.add_argument("--ideal", action="store_true",
                        help="the ideal robot: kinematic, ground-truth odometry, free compute (the first benchmark)")
    parser.add_argument("--robot", default="jackal-barn", choices=("jackal-barn", "jackal-wheeled"),
                        help="robot of the realistic configuration (default jackal-barn: skid-steer model)")
    parser.add_argument("--free-compute", action="store_true",
                        help="do not charge the navigator's compute time (reproducible runs, no deadline accounting)")
    parser.add_argument("--dynabarn", action="store_true", help="the moving-obstacle set (60 worlds, 20 m) instead of BARN")
    parser.add_argument("--noisy-odometry", action="store_true",
                        help="with --ideal: navigate on drifting wheel odometry with 2%% slip instead of ground truth")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="run N trials at a time (one core each; the scores do not change: in-process the "
                             "compute charge is CPU time, through the processes the clock is lock-step)")
    parser.add_argument("--logs", type=Path, default=None, metavar="DIR",
                        help="through the processes: keep the system log of every trial that did not reach the "
                             "goal here (world_<idx>_seed_<seed>.log), to see why")
    parser.add_argument("--results", type=Path, default=None, metavar="FILE",
                        help="append every finished trial to this JSON-lines file and skip trials already in it "
                             "(resume an interrupted run; the file must be of the same configuration)")
    parser.add_argument("--report", type=Path, default=None, metavar="FILE",
                        help="run nothing: summarize a --results file (overall, tune and test splits, failures), "
                             "also while its run goes on")
    parser.add_argument("--against", type=Path, default=None, metavar="FILE",
                        help="with --report: compare with another results file on the world-seed pairs both hold "
                             "(the same trials on two versions of the code), and list the worlds whose outcomes differ")
    parser.add_argument("--plot", type=Path, default=None, metavar="PICTURE",
                        help="with --report: draw every trial's outcome, world by seed, into this .png/.svg/.pdf "
                             "(with --against, both files on the pairs both hold)")
    parser.add_argument("--no-swept-check", dest="swept_check", action="store_false",
                        help="through the processes: turn the DriveManager's swept-footprint check off (the safety "
                             "zones alone), to measure what it changes (docs/safety.md)")
    parser.add_argument("--wall-timeout", type=float, default=600.0, metavar="S",
                        help="through the processes: a trial with no result after S s of wall time counts as a "
                             "system failure (default 600; the clock is lock-step, so a loaded machine needs more)")
    from .generate import add_generate_arguments

    add_generate_arguments(parser)  # --generate N, --generated-dir DIR (docs/barn-generated.md)


def summarize(results: list[EpisodeResult], seeds: int | None = None) -> dict:
    """Rates and mean scores over all trials (the official report), plus ``seeds`` per world."""
    from emos.actors.sim.barn_protocol import Trial, summarize_trials

    # summarize_trials reads only the score fields (success, collided, timeout, time_s, metric,
    # metric_4t, deadline_misses), which an EpisodeResult has under the same names and types.
    s = summarize_trials(cast("list[Trial]", results))
    out = {key: s[key] for key in ("success_rate", "collision_rate", "timeout_rate", "mean_metric", "metric_4t",
                                   "deadline_misses", "mean_time_s")}
    if seeds is not None:
        out["seeds"] = seeds
    return out


def _load(args: argparse.Namespace) -> tuple[dict, list[int]]:
    if args.dynabarn:
        from emos.actors.sim.dynabarn import load_dynabarn

        worlds: dict = load_dynabarn(args.worlds_file)
    else:
        from emos.actors.sim.barn_worlds import load_barn_worlds

        worlds = load_barn_worlds(_barn_source(args))
    from emos.actors.sim.barn_worlds import parse_indices

    indices = parse_indices(args.worlds) if args.worlds else list(worlds)
    if args.split != "all":
        indices = [i for i in indices if (i % 5 == 0) == (args.split == "test")]
    return worlds, indices


def _barn_source(args: argparse.Namespace) -> Path | None:
    """--worlds-file, else --barn-repo, else None (the packaged worlds)."""
    if args.worlds_file is not None and args.barn_repo is not None:
        raise ValueError("give --worlds-file or --barn-repo, not both")
    if args.barn_repo is not None and args.dynabarn:
        raise ValueError("--barn-repo reads BARN worlds; it cannot go with --dynabarn")
    source = args.worlds_file if args.worlds_file is not None else args.barn_repo
    return None if source is None else Path(source).expanduser().resolve()


def _rules(args: argparse.Namespace) -> BarnRules:
    if args.ideal and args.robot != "jackal-barn":
        raise ValueError("--robot chooses the robot of the realistic configuration; it cannot go with --ideal")
    if args.noisy_odometry and not args.ideal:
        raise ValueError("--noisy-odometry is a variant of --ideal (the realistic configuration has wheel + IMU odometry)")
    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    return BarnRules(ideal=args.ideal, robot=args.robot, noisy_odometry=args.noisy_odometry,
                     charge_compute=not args.free_compute)


def run(args: argparse.Namespace) -> int:
    from emos.actors.sim.barn_protocol import trial_seed

    from .parallel import TrialPool, in_process_trial

    if args.against is not None and args.report is None:
        raise SystemExit("emos bench barn: --against FILE compares with --report FILE; give both")
    if args.plot is not None and args.report is None:
        raise SystemExit("emos bench barn: --plot PICTURE draws a --report FILE; give both")
    if args.report is not None:
        from emos.tools.plotting import check_plot_argument

        from .report import run_comparison, run_report

        check_plot_argument(str(args.plot) if args.plot is not None else None)
        if args.against is None:
            return run_report(args.report, args.json, args.plot)
        return run_comparison(args.report, args.against, args.json, args.plot)

    if args.controller is None:
        args.controller = DYNABARN_DEFAULT_CONTROLLER if args.dynabarn else DEFAULT_CONTROLLER
    try:
        from .generate import apply_generate

        apply_generate(args)  # --generate N: N fresh worlds become the run's --worlds-file
        rules = _rules(args)
        worlds, indices = _load(args)
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
    if args.in_process:
        if not getattr(args, "swept_check", True):
            print("emos bench barn: --no-swept-check turns off the DriveManager's check; an --in-process run has "
                  "no DriveManager (run it through the processes)", file=sys.stderr)
            return 2
        if args.logs is not None:
            print("emos bench barn: --logs keeps the system logs of runs through the processes; "
                  "an --in-process run has none (use --png to see a run)", file=sys.stderr)
            return 2
        mode = ""
        systems = None
    else:
        from .process import TrialSystems

        systems = TrialSystems()
        try:
            episode = _process_episode(worlds, rules, args, systems)
        except ValueError as exc:
            print(f"emos bench barn: {exc}", file=sys.stderr)
            return 2
        mode = "supervised processes, "
    name = "DynaBARN-style" if args.dynabarn else "BARN"
    config = "ideal (kinematic, true odometry)" if rules.ideal else f"realistic ({rules.robot}, laser, wheel+IMU odometry)"
    if not getattr(args, "swept_check", True):
        config += ", swept check off"
    try:
        log = _trial_log(args, rules)
    except ValueError as exc:
        print(f"emos bench barn: {exc}", file=sys.stderr)
        return 2
    try:
        pool = TrialPool(args.jobs, args.in_process, log.append if log is not None else lambda result: None)
    except ValueError as exc:
        print(f"emos bench barn: {exc}", file=sys.stderr)
        return 2
    # Every trial not in the results file yet, started in world order (all at once with --jobs 1
    # deferred: each then runs when its world's row is due, as before).
    trials: dict[tuple[int, int], Callable[[], EpisodeResult]] = {}
    resumed: set[tuple[int, int]] = set()  # trials read back from the results file, not run now
    for idx in indices:
        key = f"dynabarn:{idx}" if args.dynabarn else idx
        for k in range(args.seeds):
            seed = trial_seed(key, k, base=args.seed)
            prior = log.get(idx, seed) if log is not None else None
            if prior is not None:
                def resumed_trial(prior: EpisodeResult = prior) -> EpisodeResult:  # this trial's
                    return prior

                trials[(idx, k)] = resumed_trial
                resumed.add((idx, k))
            elif args.in_process:
                png = args.png / f"{name.split('-')[0].lower()}_{idx:03d}_s{k}.png" if args.png else None
                trials[(idx, k)] = pool.submit(in_process_trial, worlds[idx], args.controller, rules, seed, png)
            else:
                trials[(idx, k)] = pool.submit(episode, idx, seed)
    try:
        return _report(args, indices, trials, name, config, mode, resumed)
    except BaseException:  # Ctrl-C, SIGTERM (SystemExit), an error: stop the trials in flight too
        if systems is not None:
            systems.abandon()
        raise
    finally:
        pool.close(cancel=True)
        if systems is not None:  # the last trials' systems may still be stopping (stop_in_background)
            systems.wait_stopped()


def _time_left(trials: dict, resumed: set, finished: int, wall0: float) -> str:
    """", about N min left": the trials still to run at this invocation's pace so far (trials
    read back from a results file cost nothing and do not count). ``finished``: how many of
    ``trials``, in their (world) order, are done."""
    keys = list(trials)
    ran = sum(1 for key in keys[:finished] if key not in resumed)
    to_run = sum(1 for key in keys[finished:] if key not in resumed)
    if ran <= 0 or to_run <= 0:
        return ""
    return f", about {(time.perf_counter() - wall0) / ran * to_run / 60:.0f} min left"


def _report(args: argparse.Namespace, indices: list[int], trials: dict[tuple[int, int], Callable[[], EpisodeResult]],
            name: str, config: str, mode: str, resumed: set[tuple[int, int]]) -> int:
    """A row per world as its trials finish (in world order), then the summary."""
    results: list[EpisodeResult] = []
    wall0 = time.perf_counter()
    if not args.json:
        jobs = f", {args.jobs} trials at a time" if args.jobs > 1 else ""
        print(f"{name}: {len(indices)} worlds x {args.seeds} seeds, controller {args.controller}, {config}, {mode}lock-step{jobs}")
        print(f"{'world':>5} {'success':>7} {'collide':>7} {'timeout':>7} {'time_s':>7} {'metric':>7} {'m_4t':>6} "
              f"{'misses':>6} {'wall_s':>7}  first failure")
    for n, idx in enumerate(indices, 1):
        rows = [trials[(idx, k)]() for k in range(args.seeds)]
        results.extend(rows)
        if args.json and not args.in_process:  # slow enough to want progress; stdout stays pure JSON
            ok = sum(r.success for r in rows)
            print(f"barn: world {idx} ({n}/{len(indices)}) {ok}/{len(rows)} success, "
                  f"{sum(r.wall_s for r in rows):.1f} s wall{_time_left(trials, resumed, n * args.seeds, wall0)}",
                  file=sys.stderr, flush=True)
        if not args.json:
            s = summarize(rows)
            fail = next((f"seed {k}: {r.reason}" for k, r in enumerate(rows) if not r.success), "")
            mean_t = f"{s['mean_time_s']:>7.2f}" if s["mean_time_s"] is not None else f"{'-':>7}"
            print(f"{idx:>5} {s['success_rate']:>7.2f} {s['collision_rate']:>7.2f} {s['timeout_rate']:>7.2f} {mean_t} "
                  f"{s['mean_metric']:>7.3f} {s['metric_4t']:>6.3f} {s['deadline_misses']:>6} "
                  f"{sum(r.wall_s for r in rows):>7.1f}  {fail}", flush=True)
    summary = summarize(results, args.seeds)
    if args.json:
        print(json.dumps({"worlds": [r.as_json() for r in results], "summary": summary}))
        return 0
    wall_total = time.perf_counter() - wall0
    print()
    _print_summary("all", summary, len(results))
    if not args.dynabarn and getattr(args, "generate", None) is None:  # the index % 5 split means nothing for generated worlds
        # The split: tune on idx % 5 != 0, report idx % 5 == 0 apart.
        for label, part in (("idx % 5 != 0", [r for r in results if r.idx % 5 != 0]),
                            ("idx % 5 == 0", [r for r in results if r.idx % 5 == 0])):
            if part:
                _print_summary(label, summarize(part), len(part))
    print(f"wall {wall_total:.1f} s for {len(results)} trials")
    return 0


def _trial_log(args: argparse.Namespace, rules: BarnRules) -> Any:
    """The --results file (None without it), checked against this run's configuration."""
    if args.results is None:
        return None
    from .trial_log import TrialLog

    source = _barn_source(args)
    config = {"controller": args.controller, "rules": attrs.asdict(rules), "in_process": bool(args.in_process),
              "dynabarn": bool(args.dynabarn), "seed_base": args.seed,
              "worlds": str(source) if source is not None else "packaged"}
    if not args.in_process and rules.charges_compute:
        # Through the processes the compute charge is the Simulator's (compute_deadline); files of
        # runs from before it existed (no charge there) must not be resumed as if they had it.
        config["process_compute"] = "lockstep-charged"
    if not getattr(args, "swept_check", True):
        # Recorded only when off, so files of runs with the check on (the default) still resume.
        config["swept_check"] = False
    log = TrialLog(args.results, config)
    if log.trials and not args.json:
        print(f"resuming: {len(log.trials)} trial(s) already in {args.results}")
    return log


def _print_summary(label: str, s: dict, n: int) -> None:
    mean_t = f"{s['mean_time_s']:.2f} s" if s.get("mean_time_s") is not None else "-"
    print(f"{label:<13} trials {n:>5}  success {s['success_rate']:.3f}  collision {s['collision_rate']:.3f}  "
          f"timeout {s['timeout_rate']:.3f}  mean time {mean_t}  metric {s['mean_metric']:.4f}  "
          f"metric_4t {s['metric_4t']:.4f}  deadline misses {s['deadline_misses']}")


def _process_episode(worlds: dict, rules: BarnRules, args: argparse.Namespace, systems: Any) -> Callable[[int, int], EpisodeResult]:
    """One trial through the supervised processes, as ``episode(world index, seed)``; ``systems``
    (a :class:`.process.TrialSystems`) holds the trials in flight, to stop them with the run."""
    from emos.supervisor.launched import SystemFailed

    from .process import run_episode_process
    from .stack import StackOptions

    if args.png is not None:
        args.png.mkdir(parents=True, exist_ok=True)
    if args.dynabarn and args.worlds_file is not None:
        raise ValueError("the Simulator's dynabarn:<index> worlds are the shipped set; --worlds-file with --dynabarn "
                         "needs --in-process")
    if args.logs is not None:
        args.logs.mkdir(parents=True, exist_ok=True)
    source = _barn_source(args)
    StackOptions.for_controller(args.controller, world=min(worlds))  # an unsupported controller fails here

    def episode(idx: int, seed: int) -> EpisodeResult:
        opts = StackOptions.for_controller(args.controller, world=idx, rules=rules, seed=seed, dynabarn=args.dynabarn,
                                           barn_source=None if source is None else str(source),
                                           swept_check=getattr(args, "swept_check", True))
        log = None if args.logs is None else args.logs / f"world_{idx:03d}_seed_{seed}.log"
        png = None if args.png is None else args.png / f"{'dynabarn' if args.dynabarn else 'barn'}_{idx:03d}_seed_{seed}.png"
        try:
            # Only the logs of failures are worth keeping. The system stops while the next
            # trial starts (its result is known before).
            return run_episode_process(worlds[idx], opts, wall_timeout=getattr(args, "wall_timeout", 600.0), keep_log=log,
                                       png_path=png, systems=systems, keep_log_on_success=False, stop_in_background=True)
        except SystemFailed as exc:
            # One broken system must not end a 250-world run: it counts as a failure, loudly.
            print(f"emos bench barn: world {idx} seed {seed}: system failure: {exc}", file=sys.stderr, flush=True)
            return EpisodeResult(idx, False, False, True, 0.0, 0.0, seed=seed, reason="system failure (see stderr)")

    return episode
