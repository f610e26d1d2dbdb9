"""The Monte Carlo localizer core (pure numpy): tracking, KLD-adaptive particle count,
low-variance resampling, global localization, recovery, and bad input (invalid beams, a map
without obstacles or free space, an initial pose off the map, a 1 m odometry jump)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import (
    AmclParams,
    ParticleFilter,
    kld_limit,
    low_variance_resample,
    noisy_odometry,
)
from emos.actors.nav.maps import OccupancyGridMap
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, loop_path, room_map

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)


def _params(**kw):
    base = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=90, sigma_hit=0.1,
                laser_max_range=MAX_RANGE, update_min_d=0.1, update_min_a=0.1)
    base.update(kw)
    return AmclParams(**base)


def _run(pf, grid, path, odom, scans=None):
    """Feed the path; returns the position errors and the covariance traces after each scan."""
    errors, spread = [], []
    for i, (truth, od) in enumerate(zip(path, odom)):
        ranges = cast(grid, truth) if scans is None else scans(i, truth)
        pf.update(od, ranges, BEAMS, scan_max=MAX_RANGE)
        errors.append(math.hypot(*(pf.estimate[:2] - truth[:2])))
        spread.append(float(np.trace(pf.covariance[:2, :2])))
    return np.array(errors), np.array(spread)


def test_tracking_from_a_known_start_stays_within_centimetres():
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=1)
    pf = ParticleFilter(_params(), grid, seed=1)
    pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
    errors, _ = _run(pf, grid, path, odom)
    assert np.sqrt(np.mean(errors ** 2)) < 0.05 and errors.max() < 0.15
    drift = np.hypot(*(odom[-1, :2] - path[-1, :2]))
    assert drift > 0.1, f"the odometry alone drifts ({drift:.2f} m): the filter, not luck, kept the pose"


def test_kld_limit_and_adaptive_particle_count():
    assert kld_limit(1, 0.05, 0.99, 500, 2000) == 500   # one bin: the minimum (AMCL: the maximum)
    assert kld_limit(2, 0.05, 0.99, 10, 2000) == 20     # ceil(10 * (1 - 2/9 + sqrt(2/9) * 0.99)^3)
    assert kld_limit(10_000, 0.05, 0.99, 500, 2000) == 2000
    grid, path = room_map(), loop_path()
    pf = ParticleFilter(_params(min_particles=100, max_particles=5000), grid, seed=2)
    pf.global_localization()
    assert pf.particle_count == 5000
    odom = noisy_odometry(path, NOISE, seed=2)
    _run(pf, grid, path[:60], odom[:60])
    assert 100 <= pf.particle_count < 2000, "a converged cloud needs fewer particles than a spread one"


def test_low_variance_resampling_draws_each_particle_in_proportion():
    rng = np.random.default_rng(0)
    w = np.array([0.5, 0.25, 0.125, 0.125])
    idx = low_variance_resample(w, 8, rng)
    assert np.bincount(idx, minlength=4).tolist() == [4, 2, 1, 1], "systematic: floor or ceil of n * w, here exact"


def test_global_localization_finds_the_robot():
    grid, path = room_map(), loop_path()
    ok = 0
    for seed in range(3):
        pf = ParticleFilter(_params(max_particles=20000, min_particles=1000, sigma_hit=0.2, min_ess_fraction=0.5), grid, seed=seed)
        pf.global_localization()
        odom = noisy_odometry(path, NOISE, seed=seed)
        errors, _ = _run(pf, grid, path[:60], odom[:60])
        ok += errors[-1] < 0.2
    assert ok == 3


def test_a_kidnapped_robot_is_found_again_by_injecting_random_particles():
    grid, path = room_map(), np.vstack([loop_path(), loop_path()])  # twice round the loop
    odom = noisy_odometry(path, NOISE, seed=5)
    # At scan 40 the robot is carried to the far side of the loop (the loop is symmetric about
    # the room's centre, the room is not): its odometry notices nothing.
    truth = path.copy()
    truth[40:] = path[(np.arange(40, len(path)) + 60) % len(path)]
    errors = {}
    for slow, fast in ((0.0, 0.0), (0.001, 0.1)):
        pf = ParticleFilter(_params(recovery_alpha_slow=slow, recovery_alpha_fast=fast, max_particles=5000, sigma_hit=0.2,
                                    min_ess_fraction=0.5), grid, seed=5)
        pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
        e, _ = _run(pf, grid, truth, odom)
        assert e[:40].max() < 0.15
        errors[fast] = e
    assert errors[0.1][-10:].max() < 0.2, "recovery on: found again"
    assert errors[0.0][-10:].min() > 0.5, "recovery off (Nav2's default): still lost"


def test_invalid_readings_are_ignored_and_a_scan_without_any_leaves_the_odometry_to_spread():
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=6)
    problems = []
    pf = ParticleFilter(_params(), grid, seed=6, on_problem=lambda key, msg: problems.append(msg))
    pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))

    def scans(i, truth):
        r = cast(grid, truth)
        if 20 <= i < 30:  # NaN, inf, zero and max-range readings mixed into good ones
            r[::4], r[1::4], r[2::4] = np.nan, np.inf, 0.0
            r[3::8] = MAX_RANGE
        elif 40 <= i < 50:  # nothing usable at all
            r = np.full_like(r, np.nan)
            r[::2] = 0.0
        return r

    errors, spread = _run(pf, grid, path, odom, scans)
    assert errors[20:30].max() < 0.1, "the valid beams still localize"
    assert spread[49] > 3 * spread[39], "ten scans of odometry only: the covariance grows"
    assert any("no valid beam" in p for p in problems)
    assert errors[-20:].max() < 0.15, "good scans again: back on track"


def test_maps_without_obstacles_or_free_space_and_poses_off_the_map():
    unknown = OccupancyGridMap(data=np.full((100, 100), -1, dtype=np.int8), resolution=0.05)
    pf = ParticleFilter(_params(), unknown, seed=0)
    with pytest.raises(ValueError, match="no free cell"):
        pf.global_localization()
    pf.initialize(np.array([2.0, 2.0, 0.0]))  # tracking on an unknown map: the odometry alone
    before = np.trace(pf.covariance[:2, :2])
    for k in range(1, 6):
        pf.update(np.array([0.3 * k, 0.0, 0.0]), np.full(180, 3.0), BEAMS)
    assert np.trace(pf.covariance[:2, :2]) > before and np.isfinite(pf.estimate).all()
    with pytest.raises(ValueError, match=r"initial pose \(7.00, -3.00\) is outside the map \[0.00, 5.00\] x \[0.00, 5.00\]"):
        pf.initialize(np.array([7.0, -3.0, 0.0]))
    with pytest.raises(ValueError, match="expected finite"):
        pf.initialize(np.array([np.nan, 1.0, 0.0]))


def test_a_one_metre_odometry_jump_is_reported_spreads_the_cloud_and_is_recovered():
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=7)
    odom[40:, 0] += 1.0  # the wheels slipped: the odometry says 1 m more than the robot moved
    problems = []
    pf = ParticleFilter(_params(max_particles=5000, min_ess_fraction=0.5), grid, seed=7, on_problem=lambda k, m: problems.append(m))
    pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
    errors, spread = _run(pf, grid, path, odom)
    assert any("odometry jumped" in p for p in problems), problems
    assert spread[40] > 5 * spread[39], "the jump spreads the cloud: the covariance grows"
    assert errors[45:].max() < 0.15, "the scans find the robot again"
