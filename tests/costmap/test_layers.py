"""Costmap layers against Nav2's definitions: cost values, the inflation decay, ray-traced clearing."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.costmap import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    InflationLayer,
    ObstacleLayer,
    StaticLayer,
    costs_to_occupancy,
)
from emos.actors.nav.maps import OccupancyGridMap

pytestmark = pytest.mark.unit


def _nav2_cost(distance_cells: float, resolution: float, inscribed: float, scaling: float) -> int:
    """Nav2 InflationLayer::computeCost, transcribed."""
    if distance_cells == 0:
        return 254
    if distance_cells * resolution <= inscribed:
        return 253
    factor = math.exp(-1.0 * scaling * (distance_cells * resolution - inscribed))
    return int((253 - 1) * factor)


def test_inflation_values_follow_nav2_formula_out_to_the_radius():
    res, inscribed, scaling, radius = 0.05, 0.17, 3.0, 0.55
    costs = np.zeros((41, 41), dtype=np.uint8)
    costs[20, 20] = LETHAL_OBSTACLE
    InflationLayer(inflation_radius=radius, cost_scaling_factor=scaling, inscribed_radius=inscribed).update(costs, res)
    reach = math.ceil(radius / res)
    for iy in range(41):
        for ix in range(41):
            d = math.hypot(ix - 20, iy - 20)
            expected = _nav2_cost(d, res, inscribed, scaling) if d <= reach else 0
            assert costs[iy, ix] == expected, (ix, iy, d)
    assert costs[20, 23] == INSCRIBED_INFLATED_OBSTACLE and costs[20, 24] < INSCRIBED_INFLATED_OBSTACLE


def test_inflation_only_raises_and_leaves_unknown_unless_inscribed():
    costs = np.full((1, 30), NO_INFORMATION, dtype=np.uint8)
    costs[0, 0] = LETHAL_OBSTACLE
    costs[0, 10] = 200  # higher than the decayed cost there: kept
    InflationLayer(inflation_radius=1.0, cost_scaling_factor=1.0, inscribed_radius=0.1).update(costs, 0.05)
    assert costs[0, 1] == costs[0, 2] == INSCRIBED_INFLATED_OBSTACLE
    assert costs[0, 3] == NO_INFORMATION  # unknown stays unknown below inscribed (inflate_unknown False)
    assert costs[0, 10] == 200
    with pytest.raises(ValueError, match="cost_scaling_factor"):
        InflationLayer(cost_scaling_factor=-1.0)


def test_static_layer_and_nav2_translation_table():
    grid = OccupancyGridMap(data=np.array([[-1, 0, 50, 100]]), resolution=0.1)
    costs = StaticLayer().costs(grid)
    assert costs.tolist() == [[NO_INFORMATION, 0, 0, LETHAL_OBSTACLE]]
    assert StaticLayer(lethal_cost_threshold=50, track_unknown_space=False).costs(grid).tolist() == [[0, 0, 254, 254]]
    assert costs_to_occupancy(np.array([0, 1, 252, 253, 254, 255], dtype=np.uint8)).tolist() == [0, 1, 98, 99, 100, -1]


def test_obstacle_layer_marks_hits_and_ray_traced_clearing_removes_a_moved_obstacle():
    geometry = OccupancyGridMap(data=np.zeros((60, 80), dtype=np.int8), resolution=0.05)
    layer = ObstacleLayer(geometry, obstacle_max_range=2.5, raytrace_max_range=3.0)
    pose = (0.525, 1.525, 0.0)  # the sensor at a cell centre, looking along +x
    layer.add_scan(pose, np.array([1.0]), 0.0, 0.1)
    hit = geometry.world_to_grid(np.array([1.525, 1.525]))
    assert layer.costs[hit[1], hit[0]] == LETHAL_OBSTACLE
    assert np.all(layer.costs[hit[1], 11:hit[0]] == 0)  # the beam's cells are cleared
    # The obstacle moves away: the next beam passes through its cell and clears it.
    layer.add_scan(pose, np.array([2.0]), 0.0, 0.1)
    assert layer.costs[hit[1], hit[0]] == 0
    far = geometry.world_to_grid(np.array([2.525, 1.525]))
    assert layer.costs[far[1], far[0]] == LETHAL_OBSTACLE
    # inf clears to raytrace_max_range and marks nothing; NaN beams are skipped.
    layer.add_scan(pose, np.array([np.inf, np.nan]), 0.0, math.pi / 2)
    assert layer.costs[far[1], far[0]] == 0
    assert layer.costs[hit[1] + 5, 10] == NO_INFORMATION  # the NaN beam (up) touched nothing
    # Hits beyond obstacle_max_range clear but do not mark.
    layer.add_scan(pose, np.array([2.7]), 0.0, 0.1)
    beyond = geometry.world_to_grid(np.array([3.225, 1.525]))
    assert layer.costs[beyond[1], beyond[0]] != LETHAL_OBSTACLE


def test_obstacle_layer_never_clears_the_static_walls():
    geometry = OccupancyGridMap(data=np.zeros((10, 10), dtype=np.int8), resolution=0.1)
    layer = ObstacleLayer(geometry)
    layer.add_scan((0.05, 0.55, 0.0), np.array([np.inf]), 0.0, 0.1)
    master = np.zeros((10, 10), dtype=np.uint8)
    master[5, 5] = LETHAL_OBSTACLE  # a wall the scan looked through (a glass door, a stale map)
    layer.update_master(master)
    assert master[5, 5] == LETHAL_OBSTACLE
