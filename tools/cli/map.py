"""``emos map record -o RUN.mcap``, ``emos map build RUN.mcap -o office`` and ``emos map show
office.yaml``: the map workflow.

``record`` is ``emos record`` of the scan and odometry topics (``--scan``, ``--odom``, default
``/scan`` and ``/odom``; or the topics named) of a running system, until Ctrl-C or
``--duration``: drive the robot meanwhile. Every ``emos record`` option works.

``build`` runs the graph SLAM (``emos.actors.nav.mapping.slam``) offline on a recording's
LaserScan and Odometry topics (``--scan``, ``--odom``; each scan is paired with the newest
odometry recorded before it; a scan becomes a node when the robot moved ``--min-d`` m or turned
``--min-a`` rad since the last node), with a progress line, ends with a batch optimisation of
the graph, and saves ``office.yaml`` + ``office.pgm`` (the ROS map_server format the MapServer
reads). It reads a CARMEN log (``.log``, ``.log.gz``, ``.clf``: the Radish datasets, and what
older CARMEN robots recorded) the same way, each front-laser scan at the pose the log gives it
as its odometry. ``show`` draws a saved map to a PNG (``-o``, default next to the YAML).

Record a run first with ``emos map record -o run.mcap`` (or ``emos record /scan /odom -o
run.mcap``) while driving the robot.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_arguments", "run", "build", "record_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="map_verb", required=True)
    b = sub.add_parser("build", help="offline SLAM on a recording: map_server YAML + PGM",
                       description="offline SLAM on an MCAP recording (LaserScan + Odometry) or a CARMEN log "
                                   "(.log, .log.gz, .clf: the scans at their logged poses): map_server YAML + PGM")
    b.add_argument("file", help="an MCAP recording (emos record, ros2 bag record) with a LaserScan and an Odometry "
                                "topic, or a CARMEN log (.log, .log.gz, .clf)")
    b.add_argument("-o", "--output", required=True, help="map name or path without suffix: writes NAME.yaml and NAME.pgm")
    b.add_argument("--scan", default="/scan", help="LaserScan topic (default /scan)")
    b.add_argument("--odom", default="/odom", help="Odometry topic (default /odom)")
    b.add_argument("--min-d", type=float, default=0.2, help="travel (m) that makes a scan a node (default 0.2)")
    b.add_argument("--min-a", type=float, default=0.2, help="turn (rad) that makes a scan a node (default 0.2)")
    b.add_argument("--resolution", type=float, default=0.05, help="map cell size in m (default 0.05)")
    b.add_argument("--max-range", type=float, default=30.0, help="readings at or beyond this are no echo (m)")
    b.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    r = sub.add_parser("record", help="record a running system's scans and odometry to MCAP, for `emos map build`",
                       description="emos record of the LaserScan and Odometry topics (--scan, --odom; or the topics "
                                   "given), until Ctrl-C: drive the robot around meanwhile, then `emos map build`")
    from . import record as _record

    _record.add_arguments(r)
    r.add_argument("--scan", default="/scan", help="LaserScan topic recorded when no topics are given (default /scan)")
    r.add_argument("--odom", default="/odom", help="Odometry topic recorded when no topics are given (default /odom)")
    s = sub.add_parser("show", help="draw a saved map (map_server YAML) to a PNG")
    s.add_argument("file", help="a map_server YAML")
    s.add_argument("-o", "--output", default=None, help="PNG to write (default: the YAML's name with .png)")
    from . import map_zones

    map_zones.add_parser(sub)  # emos map zones MAP.yaml list|add|set|remove|import (keepout and speed masks)


def _beams(scan: Any) -> tuple[np.ndarray, np.ndarray]:
    r = np.asarray(scan.ranges, dtype=np.float64)
    inc, a0 = float(scan.angle_increment), float(scan.angle_min)
    if not (math.isfinite(inc) and math.isfinite(a0)) or inc == 0.0:
        return r, np.zeros(0)  # the SLAM reports the count mismatch and keeps the node on odometry
    span = float(scan.angle_max) - a0
    n = int(round(span / inc)) + 1 if math.isfinite(span) else r.size
    scan_max = float(scan.range_max) if math.isfinite(scan.range_max) and scan.range_max > 0 else math.inf
    return np.where(r >= scan_max, np.inf, r), a0 + inc * np.arange(r.size if abs(n - r.size) <= 1 else n)


def _mcap_scans(args: argparse.Namespace) -> Any:
    """(odometry pose, ranges, angles) of each LaserScan of the recording, the pose the newest
    odometry recorded before it (None before the first)."""
    from emos.actors.nav.components.convert import BadInput, pose_of
    from emos.interop.mcap_read import read_bag

    odom: np.ndarray | None = None
    for m in read_bag(args.file, topics=[args.scan, args.odom]):
        msg = m.decode()
        if m.topic == args.odom:
            try:
                odom = pose_of(msg)
            except BadInput as exc:
                print(f"emos map build: {args.odom}: {exc}; odometry message skipped", file=sys.stderr)
            continue
        yield (odom, *_beams(msg))


def build(args: argparse.Namespace) -> Path:
    from emos.actors.nav.localization import build_reference_map, is_carmen, relative_pose
    from emos.actors.nav.mapping.slam import POSEGRAPH_SUFFIX, GraphSlam, SlamParams, save_posegraph
    from emos.actors.nav.maps import save_map

    carmen = is_carmen(args.file)
    max_range = args.max_range
    if carmen:
        # A CARMEN log's scans at the poses the log gives them (raw odometry in a raw log, the
        # corrected trajectory in a "corrected" one); a laser's own shorter range is its no echo.
        from emos.actors.nav.localization import read_carmen

        log = read_carmen(args.file)
        max_range = log.no_echo_range(args.max_range)
        source: Any = ((s.pose, s.ranges, s.angles) for s in log.scans)
    else:
        source = _mcap_scans(args)
    slam = GraphSlam(SlamParams(max_range=max_range), name=f"map build {args.file}" + ("" if carmen else f" ({args.scan})"))
    last: np.ndarray | None = None
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    scans = 0
    shown = 0.0
    show = not args.quiet
    for odom, r, a in source:
        scans += 1
        if odom is None:
            continue  # no odometry yet: the scan cannot be placed
        if last is not None:
            d = relative_pose(last, odom)
            if math.hypot(d[0], d[1]) < args.min_d and abs(d[2]) < args.min_a:
                continue
        slam.add(odom, r, a)
        kept.append((r, a))
        last = odom
        now = time.monotonic()
        if show and now - shown > 0.2:
            shown = now
            sys.stderr.write(f"\rmap build: {scans} scans read, {len(kept)} nodes, {len(slam.loops)} loop closures   ")
            sys.stderr.flush()
    if not kept:
        raise SystemExit(f"emos map build: {args.file}: no {args.scan} scan with {args.odom} odometry before it"
                         if not carmen else f"emos map build: {args.file}: no scan")
    poses = slam.finish()
    use = [k for k, (r, a) in enumerate(kept) if r.size == a.size]
    grid = build_reference_map(poses[use], [kept[k][0] for k in use], [kept[k][1] for k in use],
                               resolution=args.resolution, max_range=max_range)
    out = save_map(grid, Path(str(args.output)).with_suffix(".yaml") if not str(args.output).endswith(".yaml") else Path(args.output))
    # The pose graph beside it, as the Mapper saves it: a Mapper in localization mode loads it.
    p = slam.params
    graph = save_posegraph(out.with_name(out.stem + POSEGRAPH_SUFFIX), poses[use], [kept[k] for k in use],
                           resolution=p.resolution, sigma=p.sigma, max_range=p.max_range, min_range=p.min_range)
    if show:
        sys.stderr.write(f"\rmap build: {scans} scans read, {len(kept)} nodes, {len(slam.loops)} loop closures: {out} (pose graph {graph.name})\n")
    return out


def show_map(args: argparse.Namespace) -> Path:
    from emos.actors.nav.maps import load_map
    from emos.tools.plotting import draw_map, pyplot

    plt = pyplot()
    grid = load_map(args.file)
    h, w = grid.data.shape
    fig, ax = plt.subplots(figsize=(8, 8 * h / max(w, 1) + 0.5))
    draw_map(ax, grid)
    ax.set_title(f"{Path(args.file).name}: {w} x {h} cells of {grid.resolution} m")
    out = Path(args.output) if args.output else Path(args.file).with_suffix(".png")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def record_args(args: argparse.Namespace) -> argparse.Namespace:
    """``emos map record``'s arguments as ``emos record`` takes them: the scan and odometry
    topics unless topics were named."""
    out = argparse.Namespace(**vars(args))
    if not out.topics:
        out.topics = [args.scan, args.odom]
    return out


def run(args: argparse.Namespace) -> int:
    from emos.actors.nav.localization import CarmenLogError
    from emos.actors.nav.maps import MapFileError
    from emos.interop.mcap_read import NotMcapFile

    if args.map_verb == "zones":
        from . import map_zones

        return map_zones.run(args)
    if args.map_verb == "record":
        from . import record as _record

        return _record.run(record_args(args))
    try:
        if args.map_verb == "build":
            print(build(args))
        else:
            print(show_map(args))
    except (NotMcapFile, CarmenLogError, MapFileError, OSError) as exc:
        print(f"emos map {args.map_verb}: {exc}", file=sys.stderr)
        return 2
    return 0
