"""A small asymmetric room, a ray-casting laser in it and a path through it, for the
localization tests (the filter and the Localizer component)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from emos.actors.nav.maps import OccupancyGridMap

ACES_LOG = Path(__file__).parent / "data" / "aces-corrected.log.gz"

RES = 0.05
ROOM_W, ROOM_H = 10.0, 8.0
# Boxes (xmin, ymin, xmax, ymax), placed so that no two places of the room look alike.
BOXES = [(2.0, 2.0, 3.0, 2.6), (6.8, 6.0, 7.3, 7.5), (7.5, 1.0, 8.7, 1.4), (1.0, 5.5, 1.6, 6.1)]
BEAMS = np.linspace(-math.pi, math.pi, 181)[:-1]  # 180 beams, 2 degrees apart, all around
MAX_RANGE = 12.0


def room_map() -> OccupancyGridMap:
    rows, cols = int(ROOM_H / RES), int(ROOM_W / RES)
    data = np.zeros((rows, cols), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    for x0, y0, x1, y1 in BOXES:
        data[int(y0 / RES):int(math.ceil(y1 / RES)), int(x0 / RES):int(math.ceil(x1 / RES))] = 100
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def cast(grid: OccupancyGridMap, pose: np.ndarray, angles: np.ndarray = BEAMS, max_range: float = MAX_RANGE) -> np.ndarray:
    """Ranges a perfect laser at ``pose`` measures (max_range where nothing is hit)."""
    steps = np.arange(0.0, max_range, RES / 4.0)
    th = pose[2] + angles
    x = pose[0] + np.cos(th)[:, None] * steps
    y = pose[1] + np.sin(th)[:, None] * steps
    occ = grid.values_at(np.stack([x, y], axis=-1), outside=100) >= 65
    first = np.where(occ.any(axis=1), occ.argmax(axis=1), len(steps) - 1)
    out = steps[first]
    out[~occ.any(axis=1)] = max_range
    return out


def loop_path(n: int = 120) -> np.ndarray:
    """A closed loop around the middle of the room: (n, 3) poses, heading along the path."""
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    x = 5.0 + 2.8 * np.cos(t)
    y = 4.0 + 1.6 * np.sin(t)
    yaw = np.arctan2(1.6 * np.cos(t), -2.8 * np.sin(t))
    return np.column_stack([x, y, yaw])


def twin_corridors(extra: tuple[tuple[float, float, float, float], ...] = ()) -> OccupancyGridMap:
    """Two closed corridors, 12 m x 2 m, one above the other (A: y 0.1-2.1, B: y 3.1-5.1), alike
    but for the ``extra`` boxes (xmin, ymin, xmax, ymax in metres): the look-alike places of the
    global search's tests."""
    data = np.zeros((int(6.0 / RES), int(12.0 / RES)), dtype=np.int8)

    def box(x0: float, y0: float, x1: float, y1: float) -> None:
        data[int(round(y0 / RES)):int(round(y1 / RES)), int(round(x0 / RES)):int(round(x1 / RES))] = 100

    for y in (0.0, 3.0):
        box(0.0, y, 12.0, y + 0.1)
        box(0.0, y + 2.1, 12.0, y + 2.2)
        box(0.0, y, 0.1, y + 2.2)
        box(11.9, y, 12.0, y + 2.2)
    for b in extra:
        box(*b)
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def tracked_estimates(grid: OccupancyGridMap, params: list, path: np.ndarray, max_range: float,
                      noise: tuple[float, ...] = (0.01, 0.001, 0.01, 0.001), seed: int = 1) -> list[np.ndarray]:
    """The final estimate of a filter tracking ``path`` from a known start, once per parameter
    set: for the checks that a search-only option leaves tracking bit-identical."""
    from emos.actors.nav.localization import ParticleFilter, noisy_odometry

    odom = noisy_odometry(path, noise, seed=seed)
    out = []
    for p in params:
        pf = ParticleFilter(p, grid, seed=seed)
        pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
        for i in range(len(path)):
            pf.update(odom[i], cast(grid, path[i], BEAMS, max_range), BEAMS, scan_max=max_range)
        out.append(pf.estimate.copy())
    return out


def corridor_params(max_range: float, **kw):
    """The filter parameters of the twin-corridor tests (a short-range scanner, 2000 particles)."""
    from emos.actors.nav.localization import AmclParams

    base = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=90, sigma_hit=0.2,
                laser_max_range=max_range, update_min_d=0.1, update_min_a=0.1, min_particles=500, max_particles=2000,
                search_min_ess_fraction=0.5, converged_travel=0.0, search_candidates=0)
    base.update(kw)
    return AmclParams(**base)
