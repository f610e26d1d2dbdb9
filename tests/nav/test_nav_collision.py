"""fcl shapes from robot geometry, merged obstacle boxes, and the map collision checker."""
import math

import fcl
import numpy as np
import pytest

from emos.actors.nav.collision import MapCollisionChecker, geometry_to_fcl, occupied_rectangles
from emos.actors.nav.maps import OccupancyGridMap
from emos.actors.nav.robot import RobotGeometry

pytestmark = pytest.mark.unit

T = RobotGeometry.Type


def wall_grid() -> OccupancyGridMap:
    """4 m x 4 m free map, origin (0, 0), with a vertical wall filling x in [2.0, 2.1)."""
    data = np.zeros((80, 80), np.int8)
    data[:, 40:42] = 100
    return OccupancyGridMap(data=data, resolution=0.05)


@pytest.mark.parametrize(
    "gtype, params, half_x, half_y",
    [
        (T.BOX, [0.6, 0.4, 0.3], 0.3, 0.2),
        (T.CYLINDER, [0.25, 0.5], 0.25, 0.25),
        (T.SPHERE, [0.35], 0.35, 0.35),
        (T.ELLIPSOID, [0.4, 0.2, 0.1], 0.4, 0.2),
        (T.CAPSULE, [0.15, 0.6], 0.15, 0.15),
        (T.CONE, [0.3, 0.4], 0.3, 0.3),
    ],
)
def test_shape_extents_via_distance_to_the_wall(gtype, params, half_x, half_y):
    checker = MapCollisionChecker(wall_grid(), gtype, params, unknown_is_occupied=False)
    # Robot centre 1 m left of the wall face (x = 2.0): gap = 1 - half extent along x.
    assert checker.min_distance(1.0, 2.0, 0.0) == pytest.approx(1.0 - half_x, abs=1e-4)
    # Turned by 90 degrees, the y extent faces the wall.
    assert checker.min_distance(1.0, 2.0, math.pi / 2) == pytest.approx(1.0 - half_y, abs=1e-4)
    assert checker.is_valid(2.0 - half_x - 0.01, 2.0, 0.0)
    assert not checker.is_valid(2.0 - half_x + 0.01, 2.0, 0.0)
    assert checker.min_distance(2.0 - half_x + 0.01, 2.0, 0.0) == 0.0


def test_fcl_shape_types_and_parameter_errors():
    assert isinstance(geometry_to_fcl(T.BOX, [1, 2, 3]), fcl.Box)
    assert isinstance(geometry_to_fcl("cylinder", [1, 2]), fcl.Cylinder)
    assert isinstance(geometry_to_fcl(T.CONE, [1, 2]), fcl.Cone)
    with pytest.raises(ValueError, match="CYLINDER"):
        geometry_to_fcl(T.CYLINDER, [0.2])
    with pytest.raises(ValueError, match="geometry_type"):
        geometry_to_fcl("triangle", [1])


def test_rectangles_cover_mask_exactly_and_merge_runs():
    rng = np.random.default_rng(4)
    mask = rng.random((60, 70)) < 0.3
    rects = occupied_rectangles(mask)
    cover = np.zeros(mask.shape, int)
    for x0, y0, x1, y1 in rects:
        cover[y0:y1, x0:x1] += 1
    assert np.array_equal(cover, mask.astype(int))  # exact, no overlaps
    wall = np.zeros((50, 50), bool)
    wall[:, 10:12] = True
    wall[5, :] = True
    assert len(occupied_rectangles(wall)) <= 4
    assert occupied_rectangles(np.zeros((3, 3), bool)).shape == (0, 4)


def test_shortcut_agrees_with_exact_fcl_on_random_poses():
    rng = np.random.default_rng(5)
    data = np.zeros((60, 60), np.int8)
    for _ in range(25):
        x, y = rng.integers(0, 55, 2)
        data[y:y + rng.integers(1, 6), x:x + rng.integers(1, 6)] = 100
    grid = OccupancyGridMap(data=data, resolution=0.05, origin=(-1.0, 0.5, 0.4))
    for gtype, params in [(T.BOX, [0.3, 0.15, 0.2]), (T.CYLINDER, [0.12, 0.3]), (T.ELLIPSOID, [0.2, 0.1, 0.1])]:
        checker = MapCollisionChecker(grid, gtype, params)
        xmin, ymin, xmax, ymax = grid.world_bounds()
        poses = np.column_stack(
            (rng.uniform(xmin, xmax, 3000), rng.uniform(ymin, ymax, 3000), rng.uniform(-math.pi, math.pi, 3000))
        )
        fast = checker.are_valid(poses)
        exact = checker.are_valid(poses, exact=True)
        assert np.array_equal(fast, exact)
        assert 0 < fast.sum() < len(fast)
        scalar = np.array([checker.is_valid(*p) for p in poses[:300]])
        assert np.array_equal(scalar, exact[:300])


def test_unknown_and_outside_count_as_obstacles_when_asked():
    data = np.zeros((40, 40), np.int8)
    data[:, 30:] = -1
    grid = OccupancyGridMap(data=data, resolution=0.05)
    strict = MapCollisionChecker(grid, T.CYLINDER, [0.2, 0.2], unknown_is_occupied=True)
    lenient = MapCollisionChecker(grid, T.CYLINDER, [0.2, 0.2], unknown_is_occupied=False)
    # Centre 0.1 m from the unknown band at x = 1.5.
    assert not strict.is_valid(1.4, 1.0, 0.0) and lenient.is_valid(1.4, 1.0, 0.0)
    # Centre 0.1 m inside the map edge at x = 0.
    assert not strict.is_valid(0.1, 1.0, 0.0) and lenient.is_valid(0.1, 1.0, 0.0)
    assert strict.is_valid(0.75, 1.0, 0.0)
    # Outside the grid is never valid.
    assert not lenient.is_valid(-0.5, 1.0, 0.0)


def test_empty_map_distance_is_infinite():
    grid = OccupancyGridMap(data=np.zeros((10, 10), np.int8), resolution=0.1)
    checker = MapCollisionChecker(grid, T.SPHERE, [0.1], unknown_is_occupied=False)
    assert checker.min_distance(0.5, 0.5, 0.0) == math.inf
    assert checker.is_valid(0.5, 0.5, 0.0)
