"""Obstacle inflation and clearance maps built on the exact distance transform."""
from __future__ import annotations

import math

import numpy as np

from .edt import euclidean_distance_transform
from .grid import OCCUPIED, OccupancyGridMap

__all__ = ["distance_map", "inflate"]


def distance_map(
    grid: OccupancyGridMap, occupied_threshold: int = 65, unknown_is_occupied: bool = False
) -> np.ndarray:
    """Metres from each cell centre to the nearest occupied cell centre (inf if none)."""
    mask = grid.occupied_mask(occupied_threshold, unknown_is_occupied)
    return euclidean_distance_transform(mask, sampling=grid.resolution)


def inflate(
    grid: OccupancyGridMap,
    radius: float,
    occupied_threshold: int = 65,
    unknown_is_occupied: bool = False,
    inflated_value: int = OCCUPIED,
) -> OccupancyGridMap:
    """Mark every cell whose centre is within ``radius`` metres of an occupied cell centre.

    Occupied cells keep their value; inflated free or unknown cells get ``inflated_value``.
    A radius of 0 returns an unchanged copy.
    """
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError(f"inflate: radius must be a finite distance >= 0 m, got {radius!r}")
    if not 0 <= inflated_value <= 100:
        raise ValueError(f"inflate: inflated_value must be in 0..100, got {inflated_value!r}")
    data = grid.data.copy()
    if radius == 0:
        return grid.copy_with(data)
    dist = distance_map(grid, occupied_threshold, unknown_is_occupied)
    # A tiny tolerance so a radius of exactly k cells includes the cell k away despite
    # floating-point noise in sqrt(k^2) * resolution.
    near = dist <= radius + 1e-9 * grid.resolution
    # Unknown (-1) cells near an obstacle are raised too: they are below any inflated_value.
    data[near & (data < inflated_value)] = inflated_value
    return grid.copy_with(data)
