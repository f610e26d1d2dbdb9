"""The mapless navigator's parts (moved from the simulator): cost field, obstacle memory,
scan matching, arc sampler config."""
import numpy as np
import pytest

from emos.actors.nav.mapping import HitGrid
from emos.actors.nav.planning.costfield import CostField, lattice_edges

pytestmark = pytest.mark.unit


def test_costfield_routes_around_a_wall_through_its_gap():
    shape = (60, 60)
    occ = np.zeros(shape, dtype=bool)
    occ[30, :] = True
    occ[30, 45:50] = False  # a 5-cell gap
    field = CostField(shape, 0.1, lethal_radius=0.15, inflation_radius=0.5)
    field.compute(occ, (55, 10))
    path = np.array(field.path_from((5, 10)))
    assert tuple(path[0]) == (5, 10) and tuple(path[-1]) == (55, 10)
    crossing = path[path[:, 0] == 30]
    assert np.all((crossing[:, 1] >= 45) & (crossing[:, 1] < 50))
    occ[30, 45:50] = True  # closed: unreachable
    field.compute(occ, (55, 10))
    assert field.path_from((5, 10)) == []
    assert len(lattice_edges((3, 4))[0]) == 29


def test_hit_grid_keeps_exact_points():
    grid = HitGrid((0, 0, 2, 2), 0.1)
    assert grid.insert(np.array([[0.51, 0.52], [0.53, 0.54], [5.0, 5.0]])) == 1  # same cell, one outside
    pts = grid.points_near((0.5, 0.5), 0.2)
    assert pts.tolist() == [[0.53, 0.54]]
    with pytest.raises(ValueError, match="HitGrid"):
        HitGrid((0, 0, 0, 1), 0.1)


def test_virtual_blocks_close_plans_but_are_not_obstacle_points():
    grid = HitGrid((0, 0, 2, 2), 0.1)
    grid.insert(np.array([[0.25, 0.25]]))
    v0 = grid.version
    grid.block(np.array([[1.05, 1.05]]))
    assert grid.version > v0
    blocked, xy = grid.blocked()
    assert blocked[10, 10] and blocked[2, 2] and blocked.sum() == 2
    assert xy[10, 10].tolist() == [1.05, 1.05]
    assert grid.points_near((1.0, 1.0), 0.3).shape == (0, 2)  # never a collision point
    grid.clear_blocks()
    assert grid.blocked()[0].sum() == 1


def test_carving_clears_ghosts_crossed_by_beams_but_keeps_grazed_obstacles():
    grid = HitGrid((0, 0, 4, 4), 0.05)
    grid.insert(np.array([[2.0, 1.0], [2.0, 2.06]]))  # a ghost on the beam line, a point 6 cm off it
    d = np.array([[1.0, 0.0], [1.0, 0.0]])
    cleared = grid.carve((0.5, 1.0), d[:1], np.array([3.0]))
    assert cleared == 1 and grid.points_near((2.0, 1.0), 0.1).shape == (0, 2)
    grid.insert(np.array([[2.0, 1.0]]))
    grid.carve((0.5, 2.04), d[:1], np.array([3.0]))  # grazes the point at y = 2.06 (2 cm off)
    assert grid.points_near((2.0, 2.06), 0.01).shape == (1, 2)
    grid.carve((0.5, 1.0), d[:1], np.array([1.4]))  # beam ends before the hit: kept
    assert grid.points_near((2.0, 1.0), 0.01).shape == (1, 2)


def test_scan_matcher_recovers_a_pose_offset():
    from emos.actors.nav.mapping import ScanMatcher, compose, correction_between

    rng = np.random.default_rng(0)
    # An L-shaped room corner plus a few posts, remembered in the grid.
    wall = np.r_[np.c_[np.linspace(0, 4, 200), np.zeros(200)], np.c_[np.zeros(200), np.linspace(0, 4, 200)]]
    posts = rng.uniform(0.5, 3.5, (8, 2))
    world_pts = np.r_[wall, posts]
    grid = HitGrid((-1, -1, 5, 5), 0.05)
    grid.insert(world_pts)
    true_pose = np.array([2.0, 1.5, 0.3])
    c, s = np.cos(true_pose[2]), np.sin(true_pose[2])
    rel = world_pts - true_pose[:2]
    local = np.c_[c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]  # the scan, robot frame
    guess = true_pose + np.array([0.06, -0.08, 0.03])  # drifted odometry
    pose, best, at_guess = ScanMatcher().match(grid, guess, local)
    assert best > at_guess
    assert pose[:2] == pytest.approx(true_pose[:2], abs=0.025)
    assert pose[2] == pytest.approx(true_pose[2], abs=0.011)
    t = correction_between(pose, guess)
    assert compose(t, guess) == pytest.approx(pose)
    # Too little map: the guess is returned untouched.
    empty = HitGrid((-1, -1, 5, 5), 0.05)
    assert ScanMatcher().match(empty, guess, local)[0].tolist() == guess.tolist()


@pytest.mark.parametrize("kwargs", [dict(speeds=1), dict(horizon=0), dict(margin=-0.1), dict(step=float("nan"))])
def test_arc_config_rejects_bad_values(kwargs):
    from emos.actors.nav.controllers.arcs import ArcConfig

    with pytest.raises(ValueError, match="ArcConfig"):
        ArcConfig(**kwargs)
