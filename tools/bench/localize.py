"""``emos bench localize``: Monte Carlo localization on real lidar logs (CARMEN format).

What is measured, on one log:

- The map: built from the log's reference trajectory and scans (``build_reference_map``:
  log-odds ray casting, 5 cm cells, readings beyond ``--max-range`` are no echo).
- The odometry: the reference's increments with seeded noise from the AMCL odometry model
  (``--noise`` alpha1..alpha4; seed = trial number), chained from the first reference pose, so
  it drifts like a robot's.
- Tracking (default): the filter starts at the first reference pose (spread: 0.1 m, 0.1 m,
  3 deg standard deviations) and follows the whole log; one trial per seed. Errors are taken at
  every scan against the reference pose.
- ``--global``: the filter starts with particles spread over the whole free space, at a seeded
  random scan of the log, and runs for 20 m of travel; one trial per seed. A trial converged
  when the error is below 0.2 m at the first scan past 10 m of travel (``converged_rate``); it
  kept the pose when the error stays below 0.2 m at every scan from there to 20 m
  (``kept_rate``). RMSE is over the scans past 10 m of every trial. Time to converge: the
  first scan from which the error stays below 0.2 m to the trial's end (``settled_rate``, and
  the median and maximum travel ``settled_m_*``, scans ``settled_scans_*`` and filter CPU
  ``settled_cpu_s_*`` up to it, over the trials that settled). The filter's own verdict:
  ``search_ended_rate``, the trials whose search ended (one hypothesis held ``converged_weight``)
  within 10 m, and ``false_convergence_rate``, those whose search ended on a wrong place.

``--json`` prints ``{"results": [{"localizer": "emos", "position_rmse_m", "heading_rmse_deg",
"converged_rate", "cpu_s_per_scan", ...}]}``; ``cpu_s_per_scan`` is process CPU time per scan
on one core (filter only; the map is built before).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_arguments", "run", "prepare", "run_tracking", "run_global", "DEFAULT_NOISE"]

#: The benchmark's odometry noise (alpha1..alpha4 of the AMCL odometry model): 10 % standard
#: deviation on each turn and on each translation, 1.8 deg of heading per metre driven, 3 cm of
#: translation per radian turned.
DEFAULT_NOISE = (0.01, 0.001, 0.01, 0.001)


def _floats(text: str, count: int, what: str) -> tuple[float, ...]:
    vals = tuple(float(v) for v in text.split(","))
    if len(vals) != count or not all(math.isfinite(v) and v >= 0 for v in vals):
        raise argparse.ArgumentTypeError(f"{what}: expected {count} comma-separated numbers >= 0, got {text!r}")
    return vals


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log", required=True, help="CARMEN log (.log or .log.gz) with FLASER lines")
    parser.add_argument("--global", dest="global_", action="store_true", help="global localization from an unknown start")
    parser.add_argument("--seeds", type=int, default=3, help="trials (seeds 0..N-1; default 3)")
    parser.add_argument("--seed-start", type=int, default=0,
                        help="first seed (trials use seeds S..S+N-1; default 0): fresh starts for a check on trials not tuned on")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--noise", default=",".join(map(str, DEFAULT_NOISE)),
                        help="odometry noise alpha1..alpha4 (default %(default)s)")
    parser.add_argument("--alphas", default=None, help="the filter's alpha1..alpha4 (default: the noise's, x2)")
    parser.add_argument("--min-particles", type=int, default=None, help="default 500 (global: 2000)")
    parser.add_argument("--max-particles", type=int, default=None, help="default 2000 (global: 20000)")
    parser.add_argument("--max-beams", type=int, default=None, help="beams per scan the filter scores (default: all, 180)")
    parser.add_argument("--sigma-hit", type=float, default=None, help="default 0.15 (global: 0.2)")
    parser.add_argument("--min-ess", type=float, default=None, help="min_ess_fraction: tempering while tracking (default 0)")
    parser.add_argument("--search-min-ess", type=float, default=None,
                        help="search_min_ess_fraction: tempering during a global search (default 0.5)")
    parser.add_argument("--hypothesis-beta", type=float, default=None,
                        help="hypothesis_beta: weigh the search's hypotheses by their scan-matched peaks (default 0.2; 0: off)")
    parser.add_argument("--converged-weight", type=float, default=None,
                        help="converged_weight: the heaviest hypothesis's share that ends a global search (default 0.95)")
    parser.add_argument("--converged-travel", type=float, default=None,
                        help="converged_travel: metres of travel over which that hypothesis must keep its share (default: the filter's)")
    parser.add_argument("--search-candidates", type=int, default=None,
                        help="search_candidates: random poses scored per search scan to propose new places (default 20000; 0: off)")
    parser.add_argument("--runner-up-nats", type=float, default=None,
                        help="runner_up_nats: keep the search's runner-up hypotheses after it ends while they trail the "
                             "leader by at most this many nats (default: the filter's)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="any other filter parameter (AmclParams name), e.g. --param runner_up_particles=500")
    parser.add_argument("--max-range", type=float, default=None,
                        help="readings at or beyond this are no echo (m; default 30, or the laser's own range when "
                             "the log declares a shorter one)")
    parser.add_argument("--field", choices=("bilinear", "nearest"), default="bilinear",
                        help="likelihood-field lookup: bilinear distance interpolation (default) or Nav2's nearest cell")
    parser.add_argument("--recovery", default=None,
                        help="recovery_alpha_slow,recovery_alpha_fast (default 0,0: none, as Nav2; global: 0.001,0.1)")
    parser.add_argument("--peer", choices=("amcl",), default=None,
                        help="also run Nav2's AMCL (the GPLv3 `amcl` PyPI package, installed on first use into the "
                             "benchmark-only environment $EMOS_BENCH_PEERS, default ~/.cache/emos-bench/peers, and run "
                             "there; with --global it starts from a map-wide Gaussian, as its bindings have no global "
                             "localization call)")
    parser.add_argument("--max-scans", type=int, default=None, help="use only the first N scans of the log (quick checks)")
    parser.add_argument("--plot", default=None, help="write a PNG of the first trial's estimate against the reference")


def prepare(log_path: str, max_range: float | None = None, max_scans: int | None = None) -> dict[str, Any]:
    """The log (its first ``max_scans`` scans), its beam angles, the range beyond which a reading
    is no echo (``CarmenLog.no_echo_range``) and the reference map built from it."""
    from emos.actors.nav.localization import build_reference_map, read_carmen

    log = read_carmen(log_path)
    if max_scans is not None:
        log.scans = log.scans[: max(max_scans, 2)]
    max_range = log.no_echo_range(max_range)
    angles = [s.angles for s in log.scans]
    ranges = [s.ranges for s in log.scans]
    grid = build_reference_map(log.poses, ranges, angles, resolution=0.05, max_range=max_range)
    return {"log": log, "angles": angles, "ranges": ranges, "reference": log.poses, "grid": grid, "max_range": max_range}


def _filter(data: dict[str, Any], params: Any, seed: int) -> Any:
    from emos.actors.nav.localization import ParticleFilter

    return ParticleFilter(params, data["grid"], seed=seed, on_problem=lambda key, msg: None)


def _pose_now(pf: Any, odom_now: np.ndarray) -> np.ndarray:
    """The filter's estimate carried forward by the odometry since its last sensor update (what
    the map -> odom transform gives between updates)."""
    from emos.actors.nav.localization import compose_pose, relative_pose

    ref = pf._odom_updated if pf._odom_updated is not None else odom_now
    return np.asarray(compose_pose(pf.estimate, relative_pose(ref, odom_now)))


def _errors(est: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos = np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1])
    head = np.abs((est[:, 2] - ref[:, 2] + np.pi) % (2 * np.pi) - np.pi)
    return pos, head


def run_tracking(data: dict[str, Any], params: Any, noise: tuple[float, ...], seed: int) -> dict[str, Any]:
    from emos.actors.nav.localization import noisy_odometry

    ref = data["reference"]
    odom = noisy_odometry(ref, noise, seed)  # type: ignore[arg-type]
    pf = _filter(data, params, seed)
    pf.initialize(ref[0], np.diag([0.1 ** 2, 0.1 ** 2, math.radians(3.0) ** 2]))
    est = np.zeros_like(ref)
    cpu = 0.0
    counts = []
    for i in range(len(ref)):
        t0 = time.process_time()
        pf.update(odom[i], data["ranges"][i], data["angles"][i], scan_max=data["max_range"])
        cpu += time.process_time() - t0
        est[i] = _pose_now(pf, odom[i])
        counts.append(pf.particle_count)
    pos, head = _errors(est, ref)
    return {"estimate": est, "odometry": odom, "pos": pos, "head": head, "cpu": cpu, "scans": len(ref),
            "converged": bool(pos[-1] < 0.2), "particles": float(np.mean(counts))}


def _segment(data: dict[str, Any], seed: int, trial_m: float) -> tuple[np.ndarray, int, int]:
    """The travel along the reference (m, per scan) and a global trial's scans [start, end):
    a seeded random start, ``trial_m`` of travel."""
    ref = data["reference"]
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ref[:, :2], axis=0).T))])
    starts = np.flatnonzero(travel <= travel[-1] - trial_m)
    rng = np.random.default_rng(10_000 + seed)
    s = int(starts[rng.integers(len(starts))])
    end = int(np.searchsorted(travel, travel[s] + trial_m)) + 1
    return travel, s, end


def run_global(data: dict[str, Any], params: Any, noise: tuple[float, ...], seed: int,
               converge_m: float = 10.0, trial_m: float = 20.0) -> dict[str, Any]:
    from emos.actors.nav.localization import noisy_odometry

    travel, s, end = _segment(data, seed, trial_m)
    seg = data["reference"][s:end]
    odom = noisy_odometry(seg, noise, seed)  # type: ignore[arg-type]
    pf = _filter(data, params, seed)
    pf.global_localization()
    est = np.zeros_like(seg)
    cpu = 0.0
    cpu_at = np.zeros(len(seg))
    ended = None  # the scan at which the filter's search ended (it declared itself converged)
    for j in range(len(seg)):
        t0 = time.process_time()
        pf.update(odom[j], data["ranges"][s + j], data["angles"][s + j], scan_max=data["max_range"])
        cpu += time.process_time() - t0
        cpu_at[j] = cpu
        est[j] = _pose_now(pf, odom[j])
        if ended is None and not pf.searching:
            ended = j
    pos, head = _errors(est, seg)
    moved = travel[s:end] - travel[s]
    after = moved >= converge_m
    cause = _failure_cause(pos, head, moved, after, ended)
    # A miss: how well the scan at 10 m fits near the logged pose and near the estimate (outside
    # the CPU count; see _fits_at).
    at10 = int(np.flatnonzero(after)[0]) if after.any() else None
    fits = _fits_at(pf, data, s + at10, seg[at10], est[at10]) if cause is not None and at10 is not None else (None, None)
    below = np.flatnonzero(pos < 0.2)
    # Time to converge: the first scan from which the error stays under 0.2 m to the trial's end
    # (travel and filter CPU up to it); None when the last scan is not under 0.2 m.
    above = np.flatnonzero(pos >= 0.2)
    settle = None if len(above) and above[-1] == len(seg) - 1 else (int(above[-1]) + 1 if len(above) else 0)
    return {"estimate": est, "reference": seg, "pos": pos[after], "head": head[after], "cpu": cpu, "scans": len(seg),
            "converged": bool(after.any() and pos[after][0] < 0.2), "kept": bool(after.any() and np.all(pos[after] < 0.2)),
            "start": s, "first_below_m": float(moved[below[0]]) if len(below) else None,
            "settled_m": None if settle is None else float(moved[settle]),
            "settled_scans": None if settle is None else settle + 1,
            "settled_cpu_s": None if settle is None else float(cpu_at[settle]),
            "search_ended_m": None if ended is None else float(moved[ended]),
            "search_ended_right": ended is not None and bool(pos[ended] < 0.2),
            "seed": seed, "cause": cause, "switches": int(getattr(pf, "switches", 0)),
            "error_at_10m_m": float(pos[after][0]) if after.any() else None,
            "reference_fit": fits[0], "estimate_fit": fits[1],
            "heading_error_at_10m_deg": float(np.degrees(head[after][0])) if after.any() else None}


def _fits_at(pf: Any, data: dict[str, Any], scan: int, reference: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    """How well scan ``scan`` fits the map near the logged pose and near the filter's estimate:
    the mean log-likelihood per beam (every valid beam) at the nearest likelihood peak from
    each (the filter's own peak search, reach about 0.3 m and 8 deg). A miss whose estimate
    fits better than the logged pose is one the scan itself cannot tell from the truth (the
    map or the logged pose is off there, or a look-alike place fits better); one whose logged
    pose fits better is the filter's to fix."""
    from emos.actors.nav.localization import select_beams

    r, a = select_beams(data["ranges"][scan], data["angles"][scan], 100_000, 0.0, float(data["max_range"]))
    if len(r) == 0:
        return float("nan"), float("nan")
    peaks = pf._peaks(np.array([reference, estimate], dtype=np.float64), r, a) / len(r)
    return float(peaks[0]), float(peaks[1])


#: Why a global trial did not converge (``_failure_cause``), as counted in ``failures``.
FAILURE_CAUSES = ("wrong_place", "undecided", "lost")


def _failure_cause(pos: np.ndarray, head: np.ndarray, moved: np.ndarray, after: np.ndarray, ended: int | None) -> str | None:
    """Why a global trial missed (None: it converged, error < 0.2 m at the first scan past the
    convergence travel). ``wrong_place``: the search ended (one hypothesis held
    ``converged_weight``) on a place 0.2 m or more from the truth, and the estimate was still
    wrong at the convergence travel (a symmetric or look-alike place was declared too early);
    ``undecided``: the search had not ended by then and the heaviest hypothesis was wrong (not
    enough evidence yet); ``lost``: the search ended on the right place and the estimate left it
    afterwards (tracking lost it)."""
    if not after.any():
        return "undecided"
    first = int(np.flatnonzero(after)[0])
    if pos[first] < 0.2:
        return None
    if ended is None or ended > first:
        return "undecided"
    return "lost" if pos[ended] < 0.2 else "wrong_place"


AMCL_PACKAGES = ["amcl==0.1.2"]  # Nav2's AMCL with Python bindings (GPLv3): the benchmark's peer environment only
_AMCL_TIMEOUT_S = 3600.0


def amcl_trials(data: dict[str, Any], params: Any, specs: list[dict[str, Any]], log: Any = None) -> list[tuple[np.ndarray, float]]:
    """Nav2's AMCL (``localize_peer_amcl`` in the peer environment) on the benchmark's map and
    scans, one trial per spec (``odom`` (m, 3), ``first`` scan, ``initial`` pose and its diagonal
    ``variance``), with our particle budget, motion alphas, sigma_hit, z_hit/z_rand, beams and
    recovery rates: each trial's estimates and its CPU time. Its own seed, update thresholds and
    likelihood distance cap are not settable through its bindings."""
    import tempfile

    from emos.tools.bench import peer_env

    python = peer_env.ensure("amcl", AMCL_PACKAGES, "amcl", log=log)
    script = Path(__file__).with_name("localize_peer_amcl.py")
    g = data["grid"]
    # Nav2's AMCL reads 100 as occupied, 0 as free and anything else as unknown (its convertMap):
    # the map as map_server's trinary thresholds give it (0.65 / 0.25, the thresholds our filter
    # uses too). Cells as rows of y, the origin at the lower-left corner, as these bindings take it.
    cells = np.where(g.data >= 65, 100, np.where((g.data >= 0) & (g.data <= 25), 0, -1)).astype(np.int8)
    ranges, angles = data["ranges"], data["angles"]
    offsets = np.concatenate([[0], np.cumsum([len(r) for r in ranges])])
    budget = {k: getattr(params, k) for k in ("min_particles", "max_particles", "recovery_alpha_slow", "recovery_alpha_fast",
                                              "alpha1", "alpha2", "alpha3", "alpha4", "z_hit", "z_rand", "sigma_hit",
                                              "max_beams")}
    trials = {}
    for k, spec in enumerate(specs):
        trials.update({f"odom_{k}": spec["odom"], f"first_{k}": spec["first"], f"initial_{k}": spec["initial"],
                       f"variance_{k}": spec["variance"]})
    with tempfile.TemporaryDirectory(prefix="emos-bench-amcl-") as tmp:
        given, got = Path(tmp) / "input.npz", Path(tmp) / "output.npz"
        np.savez(given, cells=cells, resolution=g.resolution, origin=np.asarray(g.origin[:2], dtype=np.float64),
                 ranges=np.concatenate(ranges).astype(np.float64), angles=np.concatenate(angles).astype(np.float64),
                 offsets=offsets, max_range=float(data["max_range"]), params=json.dumps(budget), trials=len(specs), **trials)
        if log:
            log(f"running the peer amcl: {len(specs)} trials")
        doc = peer_env.run_script("amcl", python, script, ["--input", str(given), "--output", str(got)], _AMCL_TIMEOUT_S)
        try:
            out = np.load(got)
            results = [(np.asarray(out[f"est_{k}"]), float(doc["cpu_s"][k])) for k in range(len(specs))]
        except (ValueError, KeyError, TypeError, IndexError, OSError):
            raise peer_env.PeerUnavailable(f"peer amcl printed no result: {doc!r}") from None
    for (est, _), spec in zip(results, specs):
        if est.shape != spec["odom"].shape or not np.all(np.isfinite(est)):
            raise peer_env.PeerUnavailable(f"peer amcl returned poses of shape {est.shape} for {len(spec['odom'])} scans")
    return results


def tracking_amcl_spec(data: dict[str, Any], noise: tuple[float, ...], seed: int) -> dict[str, Any]:
    """The tracking trial of ``seed`` for Nav2's AMCL: the same odometry (same seed) and map, the
    same start (the first reference pose, 0.1 m / 0.1 m / 3 deg standard deviations)."""
    from emos.actors.nav.localization import noisy_odometry

    ref = data["reference"]
    return {"odom": noisy_odometry(ref, noise, seed), "first": 0, "initial": np.asarray(ref[0], dtype=np.float64),  # type: ignore[arg-type]
            "variance": np.array([0.1 ** 2, 0.1 ** 2, math.radians(3.0) ** 2])}


def tracking_amcl_result(data: dict[str, Any], est: np.ndarray, cpu: float) -> dict[str, Any]:
    ref = data["reference"]
    pos, head = _errors(est, ref)
    return {"estimate": est, "pos": pos, "head": head, "cpu": cpu, "scans": len(ref), "converged": bool(pos[-1] < 0.2)}


def global_amcl_spec(data: dict[str, Any], noise: tuple[float, ...], seed: int, trial_m: float = 20.0) -> dict[str, Any]:
    """The global trial of ``seed`` (segment, odometry) for Nav2's AMCL. Its bindings have no
    global localization call (Nav2's spreads the particles uniformly over the free cells); the
    nearest they take is an initial pose with a covariance: the mean and covariance of the free
    cells' centres and a heading variance of pi^2 / 3 (a uniform heading's), ``max_particles``
    drawn from it. For the CPU per scan on the same scans; its convergence is reported, not
    compared."""
    from emos.actors.nav.localization import noisy_odometry

    _, s, end = _segment(data, seed, trial_m)
    g = data["grid"]
    free = np.argwhere((g.data >= 0) & (g.data <= 25))[:, ::-1]  # (col, row)
    xy = g.map_to_world((free + 0.5) * g.resolution)
    mean, cov = xy.mean(axis=0), np.cov(xy.T)
    return {"odom": noisy_odometry(data["reference"][s:end], noise, seed), "first": s,  # type: ignore[arg-type]
            "initial": np.array([mean[0], mean[1], 0.0]), "variance": np.array([cov[0, 0], cov[1, 1], math.pi ** 2 / 3.0]),
            "seed": seed}


def global_amcl_result(data: dict[str, Any], spec: dict[str, Any], est: np.ndarray, cpu: float,
                       converge_m: float = 10.0, trial_m: float = 20.0) -> dict[str, Any]:
    travel, s, end = _segment(data, spec["seed"], trial_m)
    seg = data["reference"][s:end]
    pos, head = _errors(est, seg)
    after = (travel[s:end] - travel[s]) >= converge_m
    return {"estimate": est, "reference": seg, "pos": pos[after], "head": head[after], "cpu": cpu, "scans": len(seg),
            "converged": bool(after.any() and pos[after][0] < 0.2), "kept": bool(after.any() and np.all(pos[after] < 0.2))}


def run_amcl(data: dict[str, Any], params: Any, noise: tuple[float, ...], seeds: range, global_: bool,
             log: Any = None) -> list[dict[str, Any]]:
    """Nav2's AMCL on the same trials as ours (same seeds, odometry, map and budget), in one run
    of the peer."""
    if global_:
        specs = [global_amcl_spec(data, noise, seed) for seed in seeds]
        return [global_amcl_result(data, spec, est, cpu)
                for spec, (est, cpu) in zip(specs, amcl_trials(data, params, specs, log))]
    specs = [tracking_amcl_spec(data, noise, seed) for seed in seeds]
    return [tracking_amcl_result(data, est, cpu) for est, cpu in amcl_trials(data, params, specs, log)]


def _params(args: argparse.Namespace, noise: tuple[float, ...], max_range: float) -> Any:
    from emos.actors.nav.localization import AmclParams

    alphas = _floats(args.alphas, 4, "--alphas") if args.alphas else tuple(2.0 * a for a in noise)
    g = args.global_
    # The search's parameters: the filter's defaults unless given (they act only in --global).
    search = {name: getattr(args, opt) for name, opt in (("search_min_ess_fraction", "search_min_ess"),
                                                          ("hypothesis_beta", "hypothesis_beta"),
                                                          ("converged_weight", "converged_weight"),
                                                          ("converged_travel", "converged_travel"),
                                                          ("search_candidates", "search_candidates"),
                                                          ("runner_up_nats", "runner_up_nats"))
              if getattr(args, opt, None) is not None}
    for item in getattr(args, "param", None) or []:
        name, sep, value = item.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"--param: expected NAME=VALUE, got {item!r}")
        search[name.strip()] = json.loads(value)
    recovery = _floats(args.recovery, 2, "--recovery") if args.recovery else ((0.001, 0.1) if g else (0.0, 0.0))
    return AmclParams(alpha1=alphas[0], alpha2=alphas[1], alpha3=alphas[2], alpha4=alphas[3],
                      min_particles=args.min_particles or (2000 if g else 500),
                      max_particles=args.max_particles or (20000 if g else 2000),
                      max_beams=args.max_beams or 180, laser_max_range=max_range,
                      sigma_hit=args.sigma_hit if args.sigma_hit is not None else (0.2 if g else 0.15),
                      update_min_d=0.25, update_min_a=0.2, jump_distance=5.0, jump_angle=math.pi,
                      recovery_alpha_slow=recovery[0], recovery_alpha_fast=recovery[1],
                      min_ess_fraction=args.min_ess if args.min_ess is not None else 0.0,
                      field_interpolation=getattr(args, "field", "bilinear"), **search)


def _plot(path: str, data: dict[str, Any], trial: dict[str, Any], title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = data["grid"]
    img = np.where(g.data < 0, 0.75, 1.0 - g.data / 100.0)
    h, w = g.data.shape
    ox, oy, _ = g.origin
    fig, ax = plt.subplots(figsize=(8, 8))
    ax.imshow(img, cmap="gray", origin="lower", vmin=0, vmax=1,
              extent=(ox, ox + w * g.resolution, oy, oy + h * g.resolution))
    ref = trial.get("reference", data["reference"])
    ax.plot(ref[:, 0], ref[:, 1], "-", color="tab:green", lw=2.5, label="reference (corrected log)")
    if "odometry" in trial:
        ax.plot(trial["odometry"][:, 0], trial["odometry"][:, 1], ":", color="tab:red", lw=1, label="noisy odometry")
    ax.plot(trial["estimate"][:, 0], trial["estimate"][:, 1], "-", color="tab:blue", lw=1, label="EMOS Localizer")
    # The long free rays through doors and windows reach far out; show the building.
    lo, hi = ref[:, :2].min(axis=0) - 4.0, ref[:, :2].max(axis=0) + 4.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_title(title)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best")
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(path, dpi=75)
    plt.close(fig)


def _settling(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """Time to converge over the global trials that settled (error under 0.2 m from some scan to
    the end): median and maximum travel (m), scans and filter CPU (s) up to that scan."""
    done = [t for t in trials if t.get("settled_m") is not None]
    out: dict[str, Any] = {"settled_rate": len(done) / max(len(trials), 1)}
    for key in ("settled_m", "settled_scans", "settled_cpu_s"):
        vals = np.array([t[key] for t in done], dtype=np.float64)
        out[f"{key}_median"] = float(np.median(vals)) if len(vals) else None
        out[f"{key}_max"] = float(vals.max()) if len(vals) else None
    return out


def _search_end(trials: list[dict[str, Any]], within_m: float = 10.0) -> dict[str, Any]:
    """The filter's own verdict: the share of trials whose search ended (one hypothesis held
    ``converged_weight``) within ``within_m`` of travel, and the share that ended on a wrong
    place (error >= 0.2 m at that scan: a false convergence)."""
    ended = [t for t in trials if t["search_ended_m"] is not None]
    return {"search_ended_rate": sum(t["search_ended_m"] <= within_m for t in ended) / max(len(trials), 1),
            "false_convergence_rate": sum(not t["search_ended_right"] for t in ended) / max(len(trials), 1)}


def _row(name: str, trials: list[dict[str, Any]], global_: bool) -> dict[str, Any]:
    pos = np.concatenate([t["pos"] for t in trials])
    head = np.concatenate([t["head"] for t in trials])
    scans = sum(t["scans"] for t in trials)
    return {"localizer": name, "position_rmse_m": float(np.sqrt(np.mean(pos ** 2))) if len(pos) else float("nan"),
            "heading_rmse_deg": float(np.degrees(np.sqrt(np.mean(head ** 2)))) if len(head) else float("nan"),
            "converged_rate": float(np.mean([t["converged"] for t in trials])),
            "cpu_s_per_scan": sum(t["cpu"] for t in trials) / max(scans, 1),
            "trials": len(trials), "scans": scans,
            **({"kept_rate": float(np.mean([t["kept"] for t in trials])), **_settling(trials), **_search_end(trials),
                "runner_up_switches": sum(t.get("switches", 0) for t in trials),
                "failures": {c: sum(t.get("cause") == c for t in trials) for c in FAILURE_CAUSES},
                "failed_trials": [{"seed": t["seed"], "cause": t["cause"], "start_scan": t["start"],
                                   "error_at_10m_m": t["error_at_10m_m"], "heading_error_at_10m_deg": t["heading_error_at_10m_deg"],
                                   "search_ended_m": t["search_ended_m"], "switches": t.get("switches", 0),
                                   "reference_fit": t["reference_fit"], "estimate_fit": t["estimate_fit"]}
                                  for t in trials if t.get("cause") is not None]}
               if global_ else {}),
            "position_max_m": float(pos.max()) if len(pos) else float("nan")}


def measure(args: argparse.Namespace) -> dict[str, Any]:
    noise = _floats(args.noise, 4, "--noise")
    data = prepare(args.log, args.max_range, args.max_scans)
    params = _params(args, noise, data["max_range"])
    first = getattr(args, "seed_start", 0) or 0
    seeds = range(first, first + max(args.seeds, 1))
    trials = [(run_global if args.global_ else run_tracking)(data, params, noise, seed) for seed in seeds]
    rows = [_row("emos", trials, args.global_)]
    if args.peer == "amcl":
        rows.append(_row("amcl", run_amcl(data, params, noise, seeds, args.global_, log=_stderr), False))
    if args.plot:
        _plot(args.plot, data, trials[0], f"{data['log'].name}: {'global' if args.global_ else 'tracking'}, seed 0")
    return {"dataset": data["log"].name, "mode": "global" if args.global_ else "tracking", "noise_alphas": list(noise),
            "laser": data["log"].laser, "no_echo_range_m": data["max_range"],
            "filter": {k: getattr(params, k) for k in ("alpha1", "alpha2", "alpha3", "alpha4", "min_particles",
                                                      "max_particles", "max_beams", "sigma_hit", "z_hit", "z_rand",
                                                      "min_ess_fraction", "search_min_ess_fraction", "hypothesis_beta",
                                                      "converged_weight", "converged_travel", "search_candidates",
                                                      "runner_up_nats", "runner_up_switch_nats", "runner_up_scan_nats",
                                                      "runner_up_particles")},
            "results": rows}


def _stderr(text: str) -> None:
    import sys

    print(f"emos bench localize: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    import sys

    from emos.actors.nav.localization import CarmenLogError
    from emos.tools.bench.peer_env import PeerUnavailable

    try:
        result = measure(args)
    except (CarmenLogError, PeerUnavailable, argparse.ArgumentTypeError, ValueError) as exc:
        print(f"emos bench localize: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result))
        return 0
    from .common import table

    print(f"{result['dataset']} ({result['mode']}; odometry noise alphas {result['noise_alphas']})")
    print(table(result["results"], [("localizer", "localizer", "s"), ("position_rmse_m", "pos RMSE m", ".4f"),
                                    ("heading_rmse_deg", "head RMSE deg", ".3f"), ("converged_rate", "converged", ".2f"),
                                    ("cpu_s_per_scan", "CPU s/scan", ".4f"), ("trials", "trials", "d")]))
    return 0
