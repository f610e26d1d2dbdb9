"""Global localization's start pool (``search_start_pool``, issue 36): the search's first scan
weighs a larger pool of uniform free-space poses and starts from particles drawn where the scan
fits, weighted by the inverse of how likely each was to be drawn. More particles near the robot
than the uniform start gives, the same posterior in expectation, off by default, and never
used when tracking from a known pose. Seeded, no processes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, ParticleFilter
from emos.actors.nav.localization.likelihood import select_beams
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, loop_path, room_map

pytestmark = pytest.mark.unit


def _params(**kw):
    base = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=90, sigma_hit=0.2,
                laser_max_range=MAX_RANGE, update_min_d=0.1, update_min_a=0.1, min_particles=500,
                max_particles=3000, min_ess_fraction=0.0, search_min_ess_fraction=0.5, search_candidates=0)
    base.update(kw)
    return AmclParams(**base)


def _near(pf: ParticleFilter, truth: np.ndarray) -> np.ndarray:
    d = np.hypot(*(pf.particles[:, :2] - truth[:2]).T)
    turn = np.abs((pf.particles[:, 2] - truth[2] + math.pi) % (2 * math.pi) - math.pi)
    return (d < 0.5) & (turn < 0.3)


def _first_scan(params: AmclParams, seed: int) -> tuple[ParticleFilter, np.ndarray]:
    grid, path = room_map(), loop_path()
    pf = ParticleFilter(params, grid, seed=seed)
    pf.global_localization()
    # The odometry pose is the filter's own frame; only the scan matters for the first update.
    pf.update(path[0], cast(grid, path[0]), BEAMS, scan_max=MAX_RANGE)
    return pf, path[0]


def test_the_pool_puts_many_more_particles_near_the_robot_than_the_uniform_start():
    near_uniform, near_pool = [], []
    for seed in range(5):
        uniform, truth = _first_scan(_params(), seed)
        pooled, _ = _first_scan(_params(search_start_pool=60_000), seed)
        assert len(pooled.particles) == len(uniform.particles) == 3000  # the same budget
        near_uniform.append(int(_near(uniform, truth).sum()))
        near_pool.append(int(_near(pooled, truth).sum()))
    assert sum(near_pool) >= 5 * max(1, sum(near_uniform)), (near_uniform, near_pool)


def test_the_pool_weights_undo_the_draw():
    """Drawn from the pool, each particle weighs 1 / q (q: how likely it was to be drawn), so the
    weighted cloud is still the uniform prior: its weight near the robot is the prior's share
    there (the uniform pool's fraction of poses near it), while its particle count near the
    robot is many times that. The scan's own update then weighs them as usual."""
    grid, path = room_map(), loop_path()
    truth = path[0]
    r, a = select_beams(cast(grid, truth), BEAMS, 90, 0.0, MAX_RANGE)
    weight_near, count_near, prior_near = [], [], []
    for seed in range(6):
        pf = ParticleFilter(_params(search_start_pool=60_000), grid, seed=seed)
        pf.global_localization()
        prior_near.append(float(_near(pf, truth).mean()))  # the uniform start: the prior's share
        pf._start_from_pool(r, a)
        near = _near(pf, truth)
        weight_near.append(float(pf.weights[near].sum()))
        count_near.append(float(near.mean()))
        assert abs(pf.weights.sum() - 1.0) < 1e-9
    prior, weighted, counted = np.mean(prior_near), np.mean(weight_near), np.mean(count_near)
    assert counted > 5 * prior, (prior_near, count_near)
    assert prior / 3 < weighted < 3 * prior, (prior_near, weight_near)


def test_off_by_default_and_never_when_tracking():
    grid, path = room_map(), loop_path()
    scan = cast(grid, path[0])
    a = ParticleFilter(_params(), grid, seed=4)
    b = ParticleFilter(_params(search_start_pool=0), grid, seed=4)
    for pf in (a, b):
        pf.global_localization()
        pf.update(path[0], scan, BEAMS, scan_max=MAX_RANGE)
    np.testing.assert_array_equal(a.particles, b.particles)
    tracked = [ParticleFilter(_params(search_start_pool=pool), grid, seed=5) for pool in (0, 60_000)]
    for pf in tracked:
        pf.initialize(path[0])
        pf.update(path[0], scan, BEAMS, scan_max=MAX_RANGE)
    np.testing.assert_array_equal(tracked[0].particles, tracked[1].particles)
    np.testing.assert_array_equal(tracked[0].weights, tracked[1].weights)


def test_a_pool_no_larger_than_the_budget_is_no_pool_and_bad_values_are_refused():
    a, _ = _first_scan(_params(), 6)
    b, _ = _first_scan(_params(search_start_pool=3000), 6)
    np.testing.assert_array_equal(a.particles, b.particles)
    for bad in (-1, 2.5, float("nan")):
        with pytest.raises((ValueError, TypeError), match="search_start_pool"):
            _params(search_start_pool=bad)


def test_select_beams_is_what_the_pool_scores():
    # The pool is scored on the same beams as the particles (the update's max_beams selection).
    r, a = select_beams(cast(room_map(), loop_path()[0]), BEAMS, 90, 0.0, MAX_RANGE)
    assert 0 < len(r) <= 90
