"""How much wider an obstacle looks in a never-forgetting hit memory than in one scan.

A diagnostic for docs/benchmarks-history.md ("World 62: the obstacle memory, not the carried pose"):
a 0.15 m cylinder seen by the BARN laser (720 beams over +-2.356 rad, Gaussian range noise
0.01 m) while the robot drives 1 m towards it; every scan's hits go into a
:class:`~emos.actors.nav.mapping.hit_grid.HitGrid` of 0.05 m cells, as the LocalMapper's static
memory does (scan matching left out: the poses are exact here). Prints, for 1 to 250 scans,
the occupied cells and how far their centres lie outside the cylinder (p50, p90, max)::

    python3 scripts/memory_fattening.py
"""
from __future__ import annotations

import numpy as np

from emos.actors.nav.mapping.hit_grid import HitGrid

CENTRE, RADIUS, NOISE, RESOLUTION = np.array([2.0, 0.03]), 0.15, 0.01, 0.05
ANGLES = np.linspace(-2.35619, 2.35619, 720)


def scan_hits(position: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """World points where the beams from ``position`` end on the cylinder, with range noise."""
    directions = np.c_[np.cos(ANGLES), np.sin(ANGLES)]
    offset = position - CENTRE
    b = directions @ offset
    disc = b * b - (offset @ offset - RADIUS * RADIUS)
    ranges = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.nan)
    hit = np.isfinite(ranges) & (ranges > 0)
    noisy = ranges[hit] + rng.normal(0.0, NOISE, int(hit.sum()))
    return position + directions[hit] * noisy[:, None]


def outside_distances(scans: int, rng: np.random.Generator) -> tuple[int, np.ndarray]:
    grid = HitGrid((-1.0, -2.0, 4.0, 2.0), RESOLUTION)
    for i in range(scans):
        grid.insert(scan_hits(np.array([-0.5 + i / max(scans, 1), 0.0]), rng))
    rows, cols = np.nonzero(grid.occupied)
    x = grid.origin[0] + (cols + 0.5) * RESOLUTION
    y = grid.origin[1] + (rows + 0.5) * RESOLUTION
    return len(rows), np.hypot(x - CENTRE[0], y - CENTRE[1]) - RADIUS


if __name__ == "__main__":
    rng = np.random.default_rng(0)
    print("scans  cells  cell centres outside the cylinder: p50 / p90 / max (m)")
    for scans in (1, 10, 50, 250):
        cells, d = outside_distances(scans, rng)
        p50, p90 = np.percentile(d, [50, 90])
        print(f"{scans:5d}  {cells:5d}  {p50:.3f} / {p90:.3f} / {d.max():.3f}")
