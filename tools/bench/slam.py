"""``emos bench slam``: graph SLAM (``emos.actors.nav.mapping.slam``) on a real lidar log (CARMEN).

What is measured, on one log:

- The odometry: the log's reference poses (the Radish "corrected" trajectory) with seeded
  noise from the AMCL odometry motion model (``localization.motion.noisy_odometry``; alphas
  ``--noise``, default the localization benchmark's ``DEFAULT_NOISE``: 10 % standard deviation
  on each turn and translation, 1.8 deg of heading per metre, 3 cm per radian), chained from the
  first reference pose so that it drifts like a robot's.
- SLAM runs on the scans and that odometry, one scan at a time, then a final batch
  Levenberg-Marquardt over the graph (what ``emos map build`` does too).
- ``ate_rmse_m``: absolute trajectory error after SE(2) alignment; ``rpe_1m_rmse_m``,
  ``rpe_5m_rmse_m``: relative pose error (translation) over 1 m and 5 m of travel; the
  formulas of ``evo`` (``mapping.slam.metrics``). Against the log's reference poses.
- ``cpu_s_per_scan``: process CPU time per scan (one core: the SLAM is single-threaded numpy;
  gtsam is built without TBB threads here), the final batch optimisation included.
  ``realtime_factor``: the log's duration over the CPU time; null when the log's timestamps
  do not give a duration (the Örebro log has none; the CSAIL log's are rounded to 10 s).
- ``--map OUT.yaml``: the occupancy grid of the optimised trajectory (log-odds ray casting,
  5 cm) in map_server YAML + PGM; ``--plot OUT.png``: that map beside the reference PNG
  (``--reference``, default: the log's name with ``.png`` next to it), with the trajectories.
- ``--param NAME=VALUE`` (repeatable): set a ``SlamParams`` field for this run (e.g.
  ``--param factor_covariance=hessian --param hessian_cov_scale=50``); the result then holds
  ``params``, what was changed from the defaults.
- ``--peer karto``: also run OpenKarto, the SLAM slam_toolbox is built on (``slam_peer_karto``:
  ``yag-slam``, LGPLv3, with slam_toolbox's default matcher settings), on the same scans and the
  same noisy odometry in the same run, scored by the same formulas; its row is in ``peers``.
  Installed into the benchmark-only environment (``peer_env``) on first use, never a dependency
  of EMOS.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_arguments", "run", "measure", "KARTO_PACKAGES"]

# yag-slam imports cv2 without declaring it; its own packages are pinned, numpy is whatever they accept.
KARTO_PACKAGES = ["yag-slam==0.3.0", "karto-scanmatcher==1.0.0", "sparse-bundle-adjustment==0.9.6",
                  "opencv-python-headless==5.0.0.93", "numpy"]
_PEER_TIMEOUT_S = 3600.0  # one peer run on one log; only a hung peer reaches it


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log", required=True, help="CARMEN log (.log or .log.gz) with FLASER lines")
    parser.add_argument("--seed", type=int, default=0, help="odometry noise seed (default 0)")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")
    parser.add_argument("--noise", default=None, help="odometry noise alpha1..alpha4 (default: bench localize's)")
    parser.add_argument("--max-range", type=float, default=None,
                        help="readings at or beyond this are no echo (m; default 30, or the laser's own range when "
                             "the log declares a shorter one)")
    parser.add_argument("--scans", type=int, default=0, help="use only the first N scans (0: all)")
    parser.add_argument("--map", default=None, help="save the built map as map_server YAML + PGM here")
    parser.add_argument("--plot", default=None, help="write a PNG of the built map beside the reference map")
    parser.add_argument("--reference", default=None, help="reference map PNG for --plot (default: LOG's name .png)")
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="set a SlamParams field (repeatable), e.g. --param factor_covariance=response")
    parser.add_argument("--peer", choices=("karto",), default=None,
                        help="also run OpenKarto (slam_toolbox's SLAM, the LGPLv3 `yag-slam` package, installed by the "
                             "benchmark into its own environment) on the same scans and odometry")


def _params(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` pairs as SlamParams keyword arguments: the value is read as JSON when it
    parses (numbers, lists) and as a plain string otherwise; a field SlamParams lacks is an error."""
    from emos.actors.nav.mapping.slam import SlamParams

    known = {f.name for f in SlamParams.__attrs_attrs__}
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or name not in known:
            raise SystemExit(f"--param: expected NAME=VALUE with NAME a SlamParams field ({', '.join(sorted(known))}), "
                             f"got {item!r}")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        out[name] = tuple(value) if isinstance(value, list) else value
    return out


def _noise(text: str | None) -> tuple[float, float, float, float]:
    from .localize import DEFAULT_NOISE

    if text is None:
        return (DEFAULT_NOISE[0], DEFAULT_NOISE[1], DEFAULT_NOISE[2], DEFAULT_NOISE[3])
    vals = tuple(float(v) for v in text.split(","))
    if len(vals) != 4 or not all(math.isfinite(v) and v >= 0 for v in vals):
        raise SystemExit(f"--noise: expected 4 comma-separated numbers >= 0, got {text!r}")
    return vals[0], vals[1], vals[2], vals[3]


def _duration(scans: list[Any]) -> float | None:
    """The log's duration (s) from its scans' timestamps; None when they cannot give one: all
    equal (the Örebro log has none), or too coarse (printed with 6 significant digits, as in the
    CSAIL log, they step by 10 s: fewer distinct values than half the scans)."""
    stamps = np.array([s.timestamp for s in scans], dtype=np.float64)
    if len(stamps) < 2 or len(np.unique(stamps)) < len(stamps) / 2:
        return None
    span = float(stamps.max() - stamps.min())
    return span if span > 0 else None


class _Progress:
    """One self-overwriting line on stderr (stdout stays pure JSON)."""

    def __init__(self, total: int, label: str, enabled: bool) -> None:
        self.total, self.label, self.enabled = total, label, enabled
        self._last = -1.0

    def show(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if done < self.total and now - self._last < 0.2:
            return
        self._last = now
        width = 30
        fill = int(width * done / max(self.total, 1))
        sys.stderr.write(f"\r{self.label} [{'#' * fill}{'.' * (width - fill)}] {done}/{self.total} {extra}   ")
        if done >= self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def measure(args: argparse.Namespace) -> dict[str, Any]:
    from emos.actors.nav.localization import noisy_odometry, read_carmen
    from emos.actors.nav.mapping.slam import GraphSlam, SlamParams, ate_rmse, rpe_rmse

    noise = _noise(args.noise)
    log = read_carmen(args.log)
    scans = log.scans[: args.scans] if args.scans and args.scans > 0 else log.scans
    max_range = log.no_echo_range(args.max_range)
    ref = np.array([s.pose for s in scans], dtype=np.float64)
    odom = noisy_odometry(ref, noise, args.seed)
    overrides = _params(getattr(args, "param", []) or [])
    base: dict[str, Any] = {"max_range": max_range, "odom_alphas": tuple(2.0 * a for a in noise)}
    params = SlamParams(**{**base, **overrides})
    slam = GraphSlam(params, name=f"bench slam {log.name}")
    # The progress line goes to stderr: shown unless --quiet, and with --json only on a terminal.
    progress = _Progress(len(scans), f"SLAM {log.name}", enabled=not args.quiet and (not args.json or sys.stderr.isatty()))
    t0 = time.process_time()
    for i, scan in enumerate(scans):
        slam.add(odom[i], scan.ranges, scan.angles)
        progress.show(i + 1, f"loops {len(slam.loops)}")
    est = slam.finish()
    cpu = time.process_time() - t0
    duration = _duration(scans)
    result: dict[str, Any] = {
        "dataset": log.name, "scans": len(scans),
        "ate_rmse_m": ate_rmse(est, ref), "rpe_1m_rmse_m": rpe_rmse(est, ref, 1.0), "rpe_5m_rmse_m": rpe_rmse(est, ref, 5.0),
        "cpu_s_per_scan": cpu / max(len(scans), 1),
        "realtime_factor": (duration / cpu) if duration is not None and cpu > 0 else None,
        "seed": args.seed, "noise_alphas": list(noise), "odometry_ate_rmse_m": ate_rmse(odom, ref),
        "loop_closures": len(slam.loops), "log_duration_s": duration, "laser": log.laser, "no_echo_range_m": max_range,
        **({"params": {k: list(v) if isinstance(v, tuple) else v for k, v in overrides.items()}} if overrides else {}),
    }
    peer_est = None
    if getattr(args, "peer", None) == "karto":
        peer_est, peer_doc = run_karto(scans, odom, max_range, log=None if args.quiet else _stderr)
        result["peers"] = [{
            "slam": "karto", "ate_rmse_m": ate_rmse(peer_est, ref), "rpe_1m_rmse_m": rpe_rmse(peer_est, ref, 1.0),
            "rpe_5m_rmse_m": rpe_rmse(peer_est, ref, 5.0), "cpu_s_per_scan": peer_doc["cpu_s"] / max(len(scans), 1),
            "realtime_factor": (duration / peer_doc["cpu_s"]) if duration is not None and peer_doc["cpu_s"] > 0 else None,
            "loop_closures": peer_doc["loop_closures"], "about": "OpenKarto (yag-slam 0.3.0: karto-scanmatcher + SPA), "
            "slam_toolbox's default matcher settings, every scan processed"}]
    if args.map or args.plot:
        grid = _build_map(est, scans, max_range)
        if args.map:
            from emos.actors.nav.maps.map_yaml import save_map

            result["map"] = str(save_map(grid, args.map))
        if args.plot:
            reference = args.reference or _default_reference(args.log)
            peer = None if peer_est is None else (peer_est, f"OpenKarto (ATE {result['peers'][0]['ate_rmse_m']:.3f} m)")
            _plot(args.plot, grid, est, ref, reference, f"{log.name}: ATE {result['ate_rmse_m']:.3f} m, seed {args.seed}", peer)
            result["plot"] = args.plot
    return result


def _stderr(text: str) -> None:
    print(f"emos bench slam: {text}", file=sys.stderr, flush=True)


def run_karto(scans: list[Any], odom: np.ndarray, max_range: float, log: Any = None) -> tuple[np.ndarray, dict[str, Any]]:
    """OpenKarto's optimised poses for ``scans`` from ``odom`` (``slam_peer_karto`` in the peer
    environment), and its report (``cpu_s``, ``loop_closures``)."""
    import tempfile

    from emos.tools.bench import peer_env

    angles = scans[0].angles
    if any(len(s.angles) != len(angles) or not np.array_equal(s.angles, angles) for s in scans):
        counts = sorted({len(s.angles) for s in scans})
        raise peer_env.PeerUnavailable(f"peer karto: needs one laser geometry for the whole log, got beam counts {counts}"
                                       " or differing angles")
    python = peer_env.ensure("karto", KARTO_PACKAGES, "yag_slam", log=log)
    script = Path(__file__).with_name("slam_peer_karto.py")
    with tempfile.TemporaryDirectory(prefix="emos-bench-karto-") as tmp:
        given, got = Path(tmp) / "input.npz", Path(tmp) / "output.npz"
        np.savez(given, ranges=np.array([s.ranges for s in scans], dtype=np.float64), odom=odom,
                 angles=angles, max_range=max_range)
        if log:
            log(f"running the peer karto on {len(scans)} scans...")
        doc = peer_env.run_script("karto", python, script, ["--input", str(given), "--output", str(got)], _PEER_TIMEOUT_S)
        try:
            est = np.load(got)["est"]
            report = {"cpu_s": float(doc["cpu_s"]), "loop_closures": int(doc["loop_closures"])}
        except (ValueError, KeyError, TypeError, OSError):
            raise peer_env.PeerUnavailable(f"peer karto printed no result: {doc!r}") from None
    if est.shape != odom.shape or not np.all(np.isfinite(est)):
        raise peer_env.PeerUnavailable(f"peer karto returned poses of shape {est.shape} (finite: "
                                       f"{bool(np.all(np.isfinite(est)))}) for {len(odom)} scans")
    return est, report


def _build_map(poses: np.ndarray, scans: list[Any], max_range: float) -> Any:
    from emos.actors.nav.localization import build_reference_map

    return build_reference_map(poses, [s.ranges for s in scans], [s.angles for s in scans],
                               resolution=0.05, max_range=max_range)


def _default_reference(log_path: str) -> str | None:
    from emos.actors.nav.localization.carmen import carmen_stem

    base = carmen_stem(log_path)
    return base + ".png" if os.path.exists(base + ".png") else None


def _plot(path: str, grid: Any, est: np.ndarray, ref: np.ndarray, reference: str | None, title: str,
          peer: tuple[np.ndarray, str] | None = None) -> None:
    """EMOS's map with the reference (aligned to it), EMOS's trajectory and a peer's if given,
    beside the reference map picture; with a peer, a third panel: each scan's position error
    (after each trajectory's own SE(2) alignment to the reference, as the ATE counts it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from emos.actors.nav.mapping.slam import align_se2

    img = np.where(grid.data < 0, 0.8, 1.0 - grid.data / 100.0)
    h, w = grid.data.shape
    ox, oy, _ = grid.origin
    panels = 1 + (reference is not None) + (peer is not None)
    fig, axes = plt.subplots(1, panels, figsize=(7 * panels, 7), squeeze=False)
    axes = axes[0]
    ax = axes[0]
    ax.imshow(img, cmap="gray", origin="lower", vmin=0, vmax=1,
              extent=(ox, ox + w * grid.resolution, oy, oy + h * grid.resolution))
    al = align_se2(ref, est)  # the reference in the map's frame
    ax.plot(al[:, 0], al[:, 1], "-", color="tab:green", lw=2, label="reference (corrected log)")
    ax.plot(est[:, 0], est[:, 1], "-", color="tab:blue", lw=0.8, label="EMOS SLAM")
    if peer is not None:
        peer_in_map = align_se2(peer[0], est)  # the peer's trajectory in EMOS's map frame
        ax.plot(peer_in_map[:, 0], peer_in_map[:, 1], "-", color="tab:red", lw=0.8, label=peer[1])
    ax.set_title(f"EMOS SLAM map: {title}", fontsize=9)
    # Frame the walls: no-echo beams through windows paint free rays far beyond the building.
    occ_rows, occ_cols = np.nonzero(grid.data >= 65)
    if len(occ_rows):
        r = grid.resolution
        ax.set_xlim(ox + (occ_cols.min() - 20) * r, ox + (occ_cols.max() + 20) * r)
        ax.set_ylim(oy + (occ_rows.min() - 20) * r, oy + (occ_rows.max() + 20) * r)
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize=8)
    if reference is not None:
        ref_img = plt.imread(reference)
        axes[1].imshow(ref_img, cmap="gray")
        axes[1].set_title(f"reference map ({Path(str(reference)).name})", fontsize=9)
        axes[1].axis("off")
    if peer is not None:
        ex = axes[-1]
        for poses, label, color in ((est, "EMOS SLAM", "tab:blue"), (peer[0], peer[1], "tab:red")):
            err = np.hypot(*(align_se2(poses, ref)[:, :2] - ref[:, :2]).T)
            ex.plot(err, "-", color=color, lw=0.9, label=f"{label}: RMSE {np.sqrt(np.mean(err ** 2)):.3f} m")
        ex.set_xlabel("scan")
        ex.set_ylabel("position error after alignment (m)")
        ex.set_title("error against the reference, scan by scan", fontsize=9)
        ex.grid(alpha=0.3)
        ex.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from emos.actors.nav.localization import CarmenLogError
    from emos.tools.bench.peer_env import PeerUnavailable

    try:
        result = measure(args)
    except (CarmenLogError, PeerUnavailable) as exc:
        print(f"emos bench slam: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result))
        return 0
    rtf = result["realtime_factor"]
    print(f"{result['dataset']}: {result['scans']} scans, seed {result['seed']}, odometry noise alphas {result['noise_alphas']}")
    print(f"  ATE RMSE {result['ate_rmse_m']:.4f} m (odometry alone {result['odometry_ate_rmse_m']:.3f} m), "
          f"RPE 1 m {result['rpe_1m_rmse_m']:.4f} m, RPE 5 m {result['rpe_5m_rmse_m']:.4f} m")
    print(f"  CPU {result['cpu_s_per_scan'] * 1000:.1f} ms/scan, real-time factor "
          f"{'n/a (no usable timestamps)' if rtf is None else f'{rtf:.0f}x'}, loop closures {result['loop_closures']}")
    for peer in result.get("peers", []):
        prtf = peer["realtime_factor"]
        print(f"  peer {peer['slam']}: ATE RMSE {peer['ate_rmse_m']:.4f} m ({peer['ate_rmse_m'] / max(result['ate_rmse_m'], 1e-9):.1f}x "
              f"EMOS's), RPE 1 m {peer['rpe_1m_rmse_m']:.4f} m, RPE 5 m {peer['rpe_5m_rmse_m']:.4f} m, "
              f"CPU {peer['cpu_s_per_scan'] * 1000:.1f} ms/scan, real-time factor {'n/a' if prtf is None else f'{prtf:.0f}x'}, "
              f"loop closures {peer['loop_closures']}")
    for key in ("map", "plot"):
        if key in result:
            print(f"  {key}: {result[key]}")
    return 0
