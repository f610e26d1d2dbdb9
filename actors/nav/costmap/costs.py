"""Nav2's cost values and their translation to and from ``OccupancyGrid`` cells.

A costmap cell is a uint8 as in ``nav2_costmap_2d``: 0 free, 1..252 graded cost, 253 inscribed
(the robot's centre here puts the footprint in contact), 254 lethal (an obstacle), 255 unknown.
Published costmaps use Nav2's translation table (``cost_translation_table_``) so a Nav2 user
reads the same numbers in ``emos topic echo``: 0 -> 0, 253 -> 99, 254 -> 100, 255 -> -1 and
1..252 -> 1 + 97 * (c - 1) / 251.
"""
from __future__ import annotations

import numpy as np

__all__ = ["FREE_SPACE", "INSCRIBED_INFLATED_OBSTACLE", "LETHAL_OBSTACLE", "MAX_NON_OBSTACLE",
           "NO_INFORMATION", "costs_to_occupancy", "occupancy_to_costs"]

FREE_SPACE = 0
MAX_NON_OBSTACLE = 252
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255


def _translation_table() -> np.ndarray:
    table = np.empty(256, dtype=np.int8)
    table[0] = 0
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[INSCRIBED_INFLATED_OBSTACLE] = 99
    table[LETHAL_OBSTACLE] = 100
    table[NO_INFORMATION] = -1
    return table


_TO_OCCUPANCY = _translation_table()


def costs_to_occupancy(costs: np.ndarray) -> np.ndarray:
    """uint8 costs -> int8 OccupancyGrid cells (Nav2's publisher translation)."""
    return _TO_OCCUPANCY[np.asarray(costs, dtype=np.uint8)]


def occupancy_to_costs(cells: np.ndarray, lethal_threshold: int = 100, unknown_cost: int = NO_INFORMATION,
                       trinary: bool = True) -> np.ndarray:
    """OccupancyGrid cells -> uint8 costs as Nav2's StaticLayer interprets a map
    (``lethal_cost_threshold``, ``trinary_costmap``): unknown (-1) -> ``unknown_cost``, values at or
    above the threshold -> lethal, the rest free (trinary) or scaled to 0..252 (not trinary)."""
    v = np.asarray(cells, dtype=np.int16)
    out = np.zeros(v.shape, dtype=np.uint8)
    if not trinary:
        out[:] = np.clip(np.rint(v.clip(0, 100) * MAX_NON_OBSTACLE / 100.0), 0, MAX_NON_OBSTACLE).astype(np.uint8)
    out[v >= lethal_threshold] = LETHAL_OBSTACLE
    out[v < 0] = unknown_cost
    return out
