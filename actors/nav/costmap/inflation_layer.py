"""Inflation layer: Nav2's exponential cost decay around lethal cells.

For a cell ``d`` metres (cell-centre to cell-centre) from the nearest lethal cell, as
``nav2_costmap_2d::InflationLayer::computeCost``:

- ``d == 0`` -> 254 (lethal);
- ``d <= inscribed_radius`` -> 253 (inscribed: the footprint touches the obstacle);
- otherwise ``int(252 * exp(-cost_scaling_factor * (d - inscribed_radius)))``,
  for cells within ``ceil(inflation_radius / resolution)`` cells of the obstacle.

Costs only ever rise (max with the master grid); an unknown cell (255) takes the inflated cost
only when it is inscribed or lethal, or any cost with ``inflate_unknown`` (Nav2's rule).
"""
from __future__ import annotations

import math

import numpy as np

from ..maps.edt import euclidean_distance_transform
from .costs import FREE_SPACE, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION

__all__ = ["InflationLayer", "inflation_cost"]


def inflation_cost(distance_m: np.ndarray, inscribed_radius: float, cost_scaling_factor: float) -> np.ndarray:
    """Nav2's cost for cells ``distance_m`` metres from an obstacle (no cut-off at the radius)."""
    d = np.asarray(distance_m, dtype=float)
    factor = np.exp(-cost_scaling_factor * (d - inscribed_radius))
    cost = np.floor((INSCRIBED_INFLATED_OBSTACLE - 1) * np.minimum(factor, 1.0)).astype(np.int64)
    cost = np.where(d <= inscribed_radius, INSCRIBED_INFLATED_OBSTACLE, cost)
    return np.where(d == 0, LETHAL_OBSTACLE, cost).astype(np.uint8)


class InflationLayer:
    """``inflation_radius`` (m, Nav2 default 0.55), ``cost_scaling_factor`` (1/m, default 10),
    ``inscribed_radius`` (m: the robot footprint's inscribed circle), ``inflate_unknown``."""

    def __init__(self, inflation_radius: float = 0.55, cost_scaling_factor: float = 10.0,
                 inscribed_radius: float = 0.0, inflate_unknown: bool = False) -> None:
        for name, value in (("inflation_radius", inflation_radius), ("cost_scaling_factor", cost_scaling_factor),
                            ("inscribed_radius", inscribed_radius)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"InflationLayer: {name} must be a finite number >= 0, got {value!r}")
        self.inflation_radius = float(inflation_radius)
        self.cost_scaling_factor = float(cost_scaling_factor)
        self.inscribed_radius = float(inscribed_radius)
        self.inflate_unknown = bool(inflate_unknown)

    def update(self, costs: np.ndarray, resolution: float) -> np.ndarray:
        """Inflate the lethal cells of ``costs`` (uint8, modified in place and returned)."""
        lethal = costs == LETHAL_OBSTACLE
        if not lethal.any():
            return costs
        cells = euclidean_distance_transform(lethal, sampling=1.0)
        reach = max(math.ceil(self.inflation_radius / resolution - 1e-9), 0)
        # The inscribed band is always applied, even with a smaller inflation_radius (Nav2 warns).
        reach = max(reach, math.ceil(self.inscribed_radius / resolution - 1e-9))
        near = cells <= reach + 1e-9
        inflated = np.zeros(costs.shape, dtype=np.uint8)
        inflated[near] = inflation_cost(cells[near] * resolution, self.inscribed_radius, self.cost_scaling_factor)
        unknown = costs == NO_INFORMATION
        raise_known = ~unknown & (inflated > costs)
        threshold = FREE_SPACE + 1 if self.inflate_unknown else INSCRIBED_INFLATED_OBSTACLE
        raise_unknown = unknown & (inflated >= threshold)
        costs[raise_known | raise_unknown] = inflated[raise_known | raise_unknown]
        return costs

