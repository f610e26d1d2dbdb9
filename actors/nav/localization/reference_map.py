"""An occupancy grid from scans taken at known poses (log-odds ray casting).

What the localization benchmark localizes in: the map a log's reference trajectory and scans
make. Each beam marks the cells along it free and its end cell occupied, in log-odds
(``l_free`` < 0 < ``l_occ``, clamped to ``[-l_max, l_max]``); a reading at or beyond
``max_range`` (no echo) marks free space up to ``max_range`` and no obstacle. Every scan adds
at most one observation per cell (a cell that several beams of one scan cross counts once).
Cells no beam reached stay unknown (-1); the others become 0..100 by their probability.
"""
from __future__ import annotations

import math

import numpy as np

from ..maps.grid import OccupancyGridMap

__all__ = ["build_reference_map"]


def build_reference_map(poses: np.ndarray, scans: list[np.ndarray], angles: list[np.ndarray] | np.ndarray, *,
                        resolution: float = 0.05, max_range: float = 30.0, margin: float = 1.0,
                        l_occ: float = 0.85, l_free: float = -0.4, l_max: float = 5.0,
                        sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> OccupancyGridMap:
    """The grid (frame ``map``) of ``scans[i]`` (ranges) taken at ``poses[i]`` (x, y, yaw) with
    beams at ``angles[i]`` (or one angle array for all)."""
    poses = np.asarray(poses, dtype=np.float64)
    if len(poses) != len(scans) or len(poses) == 0:
        raise ValueError(f"build_reference_map: {len(poses)} poses for {len(scans)} scans")
    # A list holds one angle array per scan (their lengths may differ: np.ndim would refuse it);
    # an array is one set of angles for every scan.
    per_scan = [np.asarray(a, dtype=np.float64) for a in angles] if isinstance(angles, list) \
        else [np.asarray(angles, dtype=np.float64)] * len(scans)
    sx, sy, syaw = sensor_pose
    ends, hits, origins = [], [], []
    for pose, r, a in zip(poses, scans, per_scan):
        r = np.asarray(r, dtype=np.float64)
        ok = np.isfinite(r) & (r > 0)
        hit = ok & (r < max_range)
        rr = np.where(hit, r, max_range)[ok]
        th = pose[2] + syaw + a[ok]
        ox = pose[0] + math.cos(pose[2]) * sx - math.sin(pose[2]) * sy
        oy = pose[1] + math.sin(pose[2]) * sx + math.cos(pose[2]) * sy
        ends.append(np.column_stack([ox + rr * np.cos(th), oy + rr * np.sin(th)]))
        hits.append(hit[ok])
        origins.append((ox, oy))
    everything = np.vstack([np.vstack(ends), np.array(origins)])
    lo = everything.min(axis=0) - margin
    hi = everything.max(axis=0) + margin
    width = int(math.ceil((hi[0] - lo[0]) / resolution))
    height = int(math.ceil((hi[1] - lo[1]) / resolution))
    logodds = np.zeros(height * width)
    seen = np.zeros(height * width, dtype=bool)
    for (ox, oy), e, hit in zip(origins, ends, hits):
        if len(e) == 0:
            continue
        # Free cells: samples every half cell along each beam, short of its end cell.
        length = np.hypot(e[:, 0] - ox, e[:, 1] - oy)
        steps = np.maximum((length / (0.5 * resolution)).astype(np.int64), 1)
        beam = np.repeat(np.arange(len(e)), steps)
        frac = (np.arange(steps.sum()) - np.repeat(np.cumsum(steps) - steps, steps)) / np.repeat(steps, steps)
        px = ox + frac * (e[beam, 0] - ox)
        py = oy + frac * (e[beam, 1] - oy)
        free = np.unique(_flat(px, py, lo, resolution, width, height))
        end_cells = _flat(e[hit, 0], e[hit, 1], lo, resolution, width, height)
        occ = np.unique(end_cells)
        free = np.setdiff1d(free, occ, assume_unique=True)
        logodds[free] += l_free
        logodds[occ] += l_occ
        seen[free] = True
        seen[occ] = True
        np.clip(logodds, -l_max, l_max, out=logodds)
    prob = 1.0 - 1.0 / (1.0 + np.exp(logodds))
    data = np.where(seen, np.round(prob * 100.0), -1).astype(np.int8).reshape(height, width)
    return OccupancyGridMap(data=data, resolution=resolution, origin=(float(lo[0]), float(lo[1]), 0.0), frame_id="map")


def _flat(x: np.ndarray, y: np.ndarray, lo: np.ndarray, res: float, width: int, height: int) -> np.ndarray:
    col = np.clip(np.floor((x - lo[0]) / res).astype(np.int64), 0, width - 1)
    row = np.clip(np.floor((y - lo[1]) / res).astype(np.int64), 0, height - 1)
    return row * width + col
