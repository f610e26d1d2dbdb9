"""The OpenKarto peer of ``emos bench slam --peer karto``, run with the benchmark-only environment's
Python (``peer_env``): never imported by EMOS (it imports only numpy and the peer's packages).

Karto is the SLAM that slam_toolbox (the ROS 2 default) is built on. ``yag-slam`` (LGPLv3) is
OpenKarto's graph SLAM in Python around ``karto-scanmatcher`` (OpenKarto's correlative scan
matcher, C++, with Python bindings) and sparse bundle adjustment (SPA, Karto's original solver):
each scan is matched against the last ``scan_buffer_len`` scans from its odometry guess, linked
to the previous scan, and loop closures are searched among earlier chains within
``loop_search_dist``; a loop closure runs the optimiser, and so does the end of the log.

Reads ``--input`` (an ``.npz`` with ``ranges`` (n, beams), ``angles`` (beams), ``odom`` (n, 3) and
``max_range``), writes ``--output`` (an ``.npz`` with the optimised poses ``est`` (n, 3)) and prints
a JSON line with the CPU time and the number of loop closures. The matcher settings are
slam_toolbox's defaults (``SETTINGS``) unless ``--settings`` gives a JSON object to merge over them.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from typing import Any

import numpy as np

# slam_toolbox's defaults (mapper_params_*.yaml): the sequential matcher's correlation search
# space and the loop matcher's, the penalties, the loop search.
SEQUENTIAL = {
    "search_size": 0.5, "resolution": 0.01, "smear_deviation": 0.1,
    "distance_variance_penalty": 0.5, "angle_variance_penalty": 1.0,
    "fine_search_angle_resolution": 0.00349, "coarse_search_angle_offset": 0.349, "coarse_angle_resolution": 0.0349,
    "minimum_angle_penalty": 0.9, "minimum_distance_penalty": 0.5, "use_response_expansion": True,
}
LOOP = {**SEQUENTIAL, "search_size": 8.0, "resolution": 0.05, "smear_deviation": 0.03}
GRAPH = {"scan_buffer_len": 10, "loop_search_dist": 3.0, "loop_search_min_chain_size": 10,
         "min_response_coarse": 0.35, "min_response_fine": 0.45}
SETTINGS = {"sequential": SEQUENTIAL, "loop": LOOP, "graph": GRAPH}
MIN_RANGE = 0.05  # m: closer readings are the sensor's own housing, no echo


def _settings(text: str | None) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {k: dict(v) for k, v in SETTINGS.items()}
    if text:
        extra = json.loads(text)
        if not isinstance(extra, dict) or not set(extra) <= set(out):
            raise SystemExit(f"--settings: expected a JSON object with keys among {sorted(out)}, got {text!r}")
        for key, values in extra.items():
            out[key].update(values)
    return out


def _inputs(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    data = np.load(path)
    ranges = np.asarray(data["ranges"], dtype=np.float64)
    angles = np.asarray(data["angles"], dtype=np.float64)
    odom = np.asarray(data["odom"], dtype=np.float64)
    max_range = float(data["max_range"])
    if ranges.ndim != 2 or angles.shape != (ranges.shape[1],) or odom.shape != (ranges.shape[0], 3) or len(angles) < 2:
        raise SystemExit(f"{path}: expected ranges (n, beams), angles (beams,) and odom (n, 3), got "
                         f"{ranges.shape}, {angles.shape}, {odom.shape}")
    if not (math.isfinite(max_range) and max_range > MIN_RANGE):
        raise SystemExit(f"{path}: max_range must be a finite number above {MIN_RANGE} m, got {max_range}")
    return ranges, angles, odom, max_range


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--input", required=True)
    ap.add_argument("--output", required=True)
    ap.add_argument("--settings", default=None, help="JSON merged over SETTINGS")
    args = ap.parse_args()
    settings = _settings(args.settings)
    ranges, angles, odom, max_range = _inputs(args.input)

    from yag_slam.graph_slam import GraphSlam  # type: ignore[import-not-found]  # the peer environment only
    from yag_slam.models import LocalizedRangeScan  # type: ignore[import-not-found]
    from yag_slam.scan_matching import Scan2DMatcherCpp  # type: ignore[import-not-found]

    seq = Scan2DMatcherCpp({**settings["sequential"], "range_threshold": max_range})
    loop = Scan2DMatcherCpp({**settings["loop"], "range_threshold": max_range}, loop=True)
    slam = GraphSlam(seq, loop, **settings["graph"])
    # Karto skips readings outside [minimum range, range threshold]: "no echo" (NaN, inf, at or
    # beyond the benchmark's max_range) goes past the threshold, as the benchmark's own SLAM reads it.
    no_echo = max_range + 1.0
    usable = np.where(np.isfinite(ranges) & (ranges < max_range), ranges, no_echo)
    inc = float(angles[1] - angles[0])
    loops = 0
    t0 = time.process_time()
    with contextlib.redirect_stdout(sys.stderr):  # yag-slam prints its warnings; stdout is the result
        for r, (x, y, th) in zip(usable, odom):
            scan = LocalizedRangeScan(r.tolist(), float(angles[0]), float(angles[-1]), inc, MIN_RANGE, no_echo + 1.0,
                                      max_range, float(x), float(y), float(th))
            _, closed = slam.process_scan(scan)
            loops += bool(closed)
        slam.run_opt()
    cpu = time.process_time() - t0
    est = np.array([[n.x, n.y, n.yaw] for n in slam.opt.nodes], dtype=np.float64)
    if est.shape != odom.shape:
        raise SystemExit(f"karto returned {est.shape[0]} poses for {odom.shape[0]} scans")
    np.savez(args.output, est=est)
    print(json.dumps({"cpu_s": cpu, "loop_closures": loops, "settings": settings}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
