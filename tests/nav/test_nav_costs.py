import numpy as np
import pytest

import emos.actors.nav.costs.kernels as kernels
from emos.actors.nav.costs import (
    PathDistanceField,
    TrajectoryCostsWeights,
    evaluate_costs,
    goal_cost,
    jerk_cost,
    obstacles_cost,
    polyline_distance_exact,
    reference_path_cost,
    smoothness_cost,
)

pytestmark = pytest.mark.unit


def straight(y, n=11, length=1.0):
    x = np.linspace(0.0, length, n)
    return np.stack([x, np.full(n, y), np.zeros(n)], axis=-1)


def test_weights_defaults_and_range():
    w = TrajectoryCostsWeights()
    assert (w.reference_path_distance_weight, w.goal_distance_weight, w.obstacles_distance_weight,
            w.smoothness_weight, w.jerk_weight) == (3.0, 3.0, 1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="goal_distance_weight"):
        TrajectoryCostsWeights(goal_distance_weight=-1.0)
    with pytest.raises(ValueError, match="jerk_weight"):
        w.jerk_weight = 2e3


def test_reference_path_cost_is_mean_lateral_offset():
    path = np.array([[0.0, 0.0], [2.0, 0.0]])
    trajs = np.stack([straight(0.0), straight(0.3), straight(-0.5)])
    np.testing.assert_allclose(reference_path_cost(trajs, path), [0.0, 0.3, 0.5], atol=1e-9)


def test_goal_cost_normalized_by_path_length():
    trajs = np.stack([straight(0.0), straight(3.0)])
    # ends at (1, 0) and (1, 3); goal (4, 0); path (0, 0) -> (4, 0), length 4
    np.testing.assert_allclose(goal_cost(trajs, [4.0, 0.0], 4.0), [3.0 / 4.0, np.hypot(3, 3) / 4.0])


def test_obstacles_cost_is_inverse_clearance_in_robot_radii():
    trajs = np.stack([straight(0.0), straight(1.0)])
    obstacles = np.array([[0.5, 2.0]])
    cost = obstacles_cost(trajs, obstacles, robot_radius=0.5)
    np.testing.assert_allclose(cost, [0.5 / 1.5, 0.5 / 0.5])
    np.testing.assert_allclose(obstacles_cost(trajs, obstacles), [1.0 / 2.0, 1.0 / 1.0])  # point robot
    assert np.all(obstacles_cost(trajs, np.zeros((0, 2))) == 0.0)


def test_smoothness_and_jerk_analytic():
    # vx ramps 0, 0.1, 0.2, 0.3 with dt=0.1 and a_max=1: every step at the limit -> 1.0
    v = np.zeros((2, 4, 3))
    v[0, :, 0] = [0.0, 0.1, 0.2, 0.3]
    v[1, :, 0] = [0.0, 0.1, 0.1, 0.1]
    acc = [1.0, 1.0, 1.0]
    np.testing.assert_allclose(smoothness_cost(v, 0.1, acc), [1.0, 1.0 / 3.0], rtol=1e-6)
    # second differences: traj0 all zero; traj1: (0.1-0.2+0) = -0.1, then 0 -> mean 0.5
    np.testing.assert_allclose(jerk_cost(v, 0.1, acc), [0.0, 0.5], atol=1e-6)


def test_initial_velocity_counts_in_smoothness():
    v = np.full((1, 3, 3), 0.0)
    v[..., 2] = 0.5
    np.testing.assert_allclose(smoothness_cost(v, 0.1, [1, 1, 1.0], initial_velocity=[0, 0, 0.0]),
                               [0.5 / 0.1 / 3.0], rtol=1e-6)


def test_zero_weight_skips_the_kernel(monkeypatch):
    called = []
    monkeypatch.setattr(kernels, "jerk_cost", lambda *a, **k: called.append("jerk"))
    monkeypatch.setattr(kernels, "obstacles_cost", lambda *a, **k: called.append("obstacles"))
    w = TrajectoryCostsWeights(obstacles_distance_weight=0.0, jerk_weight=0.0)
    trajs = np.stack([straight(0.0), straight(0.2)])
    res = evaluate_costs(w, trajs, np.zeros((2, 11, 3)), reference_path=np.array([[0, 0], [1.0, 0]]),
                         goal=[1.0, 0.0], obstacles=np.array([[0.5, 0.5]]))
    assert called == []
    assert set(res.terms) == {"reference_path", "goal"}
    np.testing.assert_allclose(res.total, 3.0 * np.array([0.0, 0.2]) + 3.0 * np.array([0.0, 0.2]))


def test_distance_field_matches_exact_on_curved_path():
    th = np.linspace(0, 3 * np.pi, 800)
    path = np.stack([th, 2 * np.sin(th)], 1)
    pts = np.random.default_rng(1).uniform([-1, -4], [11, 4], (5000, 2))
    field = PathDistanceField(path, (-1, -4, 11, 4), resolution=0.05)
    exact = polyline_distance_exact(pts, path)
    approx = field.distance(pts)
    near = exact < 0.2
    assert np.max(np.abs(approx - exact)[near]) < 5e-3  # a tenth of the grid resolution
    assert np.max(np.abs(approx - exact)) < 0.1  # far away: bounded by about a grid cell
    assert np.median(np.abs(approx - exact)) < 2e-3


def test_large_problem_uses_field_and_agrees_with_dense():
    th = np.linspace(0, 6, 1000)
    path = np.stack([th, np.sin(th)], 1)
    rng = np.random.default_rng(2)
    trajs = rng.uniform([0, -2, 0], [6, 2, 0], (50, 100, 3))
    big = reference_path_cost(trajs, path)  # 50*100*999 pairs > dense limit -> field
    dense = polyline_distance_exact(trajs[..., :2], path).mean(axis=1)
    np.testing.assert_allclose(big, dense, atol=5e-3)
