"""OccupancyGridMap: ROS cell semantics, world <-> grid conversion, validation."""
import math

import numpy as np
import pytest

from emos.actors.nav.maps import OccupancyGridMap

pytestmark = pytest.mark.unit


def test_world_grid_round_trip_with_rotated_origin():
    grid = OccupancyGridMap(data=np.zeros((50, 80), np.int8), resolution=0.1, origin=(2.0, -1.0, math.pi / 6))
    rng = np.random.default_rng(0)
    cells = np.column_stack((rng.integers(0, 80, 200), rng.integers(0, 50, 200)))
    centres = grid.grid_to_world(cells)
    assert np.array_equal(grid.world_to_grid(centres), cells)
    # The centre of cell (0, 0) sits half a cell along the rotated axes from the origin.
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    np.testing.assert_allclose(grid.grid_to_world(np.array([0, 0])), [2.0 + 0.05 * (c - s), -1.0 + 0.05 * (s + c)])
    # One cell along +x of the map frame moves by resolution * (cos, sin) in the world.
    step = grid.grid_to_world(np.array([1, 0])) - grid.grid_to_world(np.array([0, 0]))
    np.testing.assert_allclose(step, [0.1 * c, 0.1 * s])


def test_values_at_and_bounds():
    data = np.zeros((4, 5), np.int8)
    data[1, 3] = 100
    data[2, 0] = -1
    grid = OccupancyGridMap(data=data, resolution=0.5, origin=(-1.0, -1.0, 0.0))
    pts = np.array([[0.75, -0.25], [-0.9, 0.1], [10.0, 0.0], [-1.01, 0.0]])
    assert grid.values_at(pts).tolist() == [100, -1, -1, -1]
    assert grid.values_at(pts, outside=100).tolist() == [100, -1, 100, 100]
    assert grid.in_bounds(grid.world_to_grid(pts)).tolist() == [True, True, False, False]
    assert grid.world_bounds() == (-1.0, -1.0, 1.5, 1.0)
    assert grid.occupied_mask().sum() == 1
    assert grid.occupied_mask(unknown_is_occupied=True).sum() == 2
    assert grid.free_mask().sum() == 18


def test_flat_layout_matches_ros_message():
    flat = np.arange(12) % 101
    grid = OccupancyGridMap.from_flat(flat, width=4, height=3, resolution=0.1)
    # index = iy * width + ix
    assert grid.data[2, 1] == flat[2 * 4 + 1]
    assert np.array_equal(grid.flat_data(), flat)
    with pytest.raises(ValueError, match="width\\*height"):
        OccupancyGridMap.from_flat(flat, width=5, height=3, resolution=0.1)


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({"data": np.full((2, 2), 101)}, ValueError, "0..100"),
        ({"data": np.full((2, 2), -2)}, ValueError, "0..100"),
        ({"data": np.zeros(4)}, ValueError, "2D"),
        ({"data": np.full((2, 2), 0.5)}, TypeError, "integer"),
        ({"resolution": 0.0}, ValueError, "resolution"),
        ({"resolution": float("nan")}, ValueError, "resolution"),
        ({"origin": (0, 0)}, ValueError, "origin"),
    ],
)
def test_invalid_grids_are_rejected(kwargs, error, message):
    args = {"data": np.zeros((2, 2), np.int8), "resolution": 0.1}
    args.update(kwargs)
    with pytest.raises(error, match=message):
        OccupancyGridMap(**args)


def test_int_values_are_range_checked_before_cast():
    # 200 would wrap to -56 in int8: it must be rejected, not wrapped.
    with pytest.raises(ValueError, match="200"):
        OccupancyGridMap(data=np.array([[0, 200]]), resolution=0.1)
