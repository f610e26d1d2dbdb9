"""The Nav2 AMCL peer of ``emos bench localize --peer amcl``, run with the benchmark-only
environment's Python (``peer_env``): never imported by EMOS (it imports only numpy and the
peer's package).

The ``amcl`` package (GPLv3) is Nav2's AMCL (its particle filter, odometry motion model and
likelihood-field laser model, in C++) with Python bindings. This script gives it the benchmark's
map, scans and odometry, one trial after another, and returns its estimate after every scan.

Reads ``--input`` (an ``.npz``): ``cells`` (rows, cols) in Nav2's trinary values (100 occupied,
0 free, -1 unknown), ``resolution`` and ``origin`` (x, y) of the map; the log's scans as
``ranges`` and ``angles`` (both flat, scan ``i`` at ``offsets[i]:offsets[i + 1]``) and
``max_range``; ``params`` (a JSON string: ``min_particles``, ``max_particles``,
``recovery_alpha_slow``, ``recovery_alpha_fast``, ``alpha1``..``alpha4``, ``z_hit``, ``z_rand``,
``sigma_hit``, ``max_beams``); and for each trial ``k``: ``odom_k`` (m, 3), ``first_k`` (the
log's scan its first odometry pose belongs to), ``initial_k`` (x, y, theta) and ``variance_k``
(the initial pose's x, y and heading variances). Writes ``--output`` (an ``.npz`` with ``est_k``
(m, 3) per trial) and prints a JSON line with each trial's CPU time (s): the scan's conversion,
the update and the mean, as the bindings need them.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np

PARAMS = ("min_particles", "max_particles", "recovery_alpha_slow", "recovery_alpha_fast", "alpha1", "alpha2",
          "alpha3", "alpha4", "z_hit", "z_rand", "sigma_hit", "max_beams")


def _fail(path: str, what: str) -> SystemExit:
    return SystemExit(f"{path}: {what}")


def _inputs(path: str) -> dict[str, Any]:
    data = np.load(path)
    out = {key: data[key] for key in data.files}
    for key in ("cells", "resolution", "origin", "ranges", "angles", "offsets", "max_range", "params", "trials"):
        if key not in out:
            raise _fail(path, f"missing {key!r}")
    cells, offsets = out["cells"], out["offsets"]
    if cells.ndim != 2 or not np.isin(cells, (-1, 0, 100)).all():
        raise _fail(path, f"cells must be a 2-D grid of -1 / 0 / 100, got shape {cells.shape}")
    if out["ranges"].shape != out["angles"].shape or offsets.ndim != 1 or offsets[0] != 0 \
            or offsets[-1] != len(out["ranges"]) or np.any(np.diff(offsets) < 1):
        raise _fail(path, "ranges and angles must be flat arrays of one length, split by increasing offsets")
    params = json.loads(str(out["params"]))
    missing = [p for p in PARAMS if p not in params]
    if missing:
        raise _fail(path, f"params lacks {missing}")
    out["params"] = params
    scans = len(offsets) - 1
    for k in range(int(out["trials"])):
        odom, first = out.get(f"odom_{k}"), out.get(f"first_{k}")
        if odom is None or first is None or odom.ndim != 2 or odom.shape[1] != 3 \
                or not 0 <= int(first) <= scans - len(odom):
            raise _fail(path, f"trial {k}: odom_{k} (m, 3) must fit the {scans} scans from first_{k}")
    return out


def _localizer(amcl: Any, data: dict[str, Any]) -> Any:
    p = data["params"]
    loc = amcl.AMCL(int(p["min_particles"]), int(p["max_particles"]), p["recovery_alpha_slow"], p["recovery_alpha_fast"],
                    amcl.MotionParameters(p["alpha1"], p["alpha2"], p["alpha3"], p["alpha4"], 0.2),
                    amcl.LaserParameters(p["z_hit"], 0.05, 0.05, p["z_rand"], p["sigma_hit"], 0.1, 0.05, int(p["max_beams"])),
                    "differential")
    origin = data["origin"]
    loc.set_map(amcl.create_occupancy_grid_from_list(data["cells"].astype(int).tolist(), float(data["resolution"]),
                                                     float(origin[0]), float(origin[1])))
    loc.set_laser_pose(amcl.Vector3D(0.0, 0.0, 0.0))
    return loc


def _trial(amcl: Any, data: dict[str, Any], k: int) -> tuple[np.ndarray, float]:
    loc = _localizer(amcl, data)
    initial, variance = data[f"initial_{k}"], data[f"variance_{k}"]
    loc.set_initial_pose(amcl.Vector3D(*map(float, initial)), amcl.create_diagonal_covariance(*map(float, variance)))
    odom, first = data[f"odom_{k}"], int(data[f"first_{k}"])
    ranges, angles, offsets = data["ranges"], data["angles"], data["offsets"]
    max_range = float(data["max_range"])
    est = np.zeros_like(odom, dtype=np.float64)
    cpu = 0.0
    for i in range(len(odom)):
        a, b = int(offsets[first + i]), int(offsets[first + i + 1])
        t0 = time.process_time()
        scan = amcl.create_laser_scan_from_list([[float(r), float(t)] for r, t in zip(ranges[a:b], angles[a:b])], max_range)
        loc.update(scan, amcl.Vector3D(*map(float, odom[i])))
        m = loc.get_pose_mean()
        cpu += time.process_time() - t0
        est[i] = (m.x, m.y, m.theta)
    return est, cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--input", required=True)
    ap.add_argument("--output", required=True)
    args = ap.parse_args()
    data = _inputs(args.input)

    import amcl  # type: ignore[import-not-found]  # the peer environment only

    estimates: dict[str, Any] = {}
    cpu: list[float] = []
    for k in range(int(data["trials"])):
        est, seconds = _trial(amcl, data, k)
        estimates[f"est_{k}"] = est
        cpu.append(seconds)
    np.savez(args.output, **estimates)
    print(json.dumps({"cpu_s": cpu}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
