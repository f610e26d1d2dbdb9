"""Beams through walls in the global search (issue 36, ``search_through_wall_nats``): the
likelihood field scores only where a beam ends, so a look-alike place whose walls stand where
the robot's beams went straight through fits as well as the robot's own place. Counting those
beams tells them apart. Seeded, no processes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, LikelihoodField, ParticleFilter, noisy_odometry
from emos.actors.nav.maps import OccupancyGridMap
from tests.localization.helpers import BEAMS, cast, corridor_params, tracked_estimates
from tests.localization.helpers import twin_corridors as corridors

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)
RANGE = 3.0
STUB = (2.0, 0.4, 2.05, 1.8)  # a 5 cm x 1.4 m wall across corridor B, offsets from its south-west corner


def twin_corridors(stub: bool = True) -> OccupancyGridMap:
    """The helpers' twin corridors with a thin wall standing across B at x = 2 (0.2 m gaps at its
    ends). From A's west end the robot's beams to the side walls beyond x = 2 cross where B's
    wall stands, and end on walls both places have."""
    x0, y0, x1, y1 = STUB
    return corridors(((x0, 3.1 + y0, x1, 3.1 + y1),) if stub else ())


ROBOT = np.array([0.8, 1.1, 0.0])
LOOK_ALIKE = ROBOT + np.array([0.0, 3.0, 0.0])


def test_through_walls_counts_the_beams_that_cross_a_wall_short_of_their_end():
    grid = twin_corridors()
    field = LikelihoodField(grid, sigma_hit=0.2, z_hit=0.5, z_rand=0.5, max_dist=2.0, laser_max_range=RANGE)
    scan = cast(grid, ROBOT, BEAMS, RANGE)
    ok = scan < RANGE
    counts = field.through_walls(np.array([ROBOT, LOOK_ALIKE]), scan[ok], BEAMS[ok], margin=0.3)
    assert counts[0] == 0, "the robot's own scan crosses no wall where it was taken"
    assert counts[1] >= 5, f"in B, the beams past x = 2 cross the thin wall: {counts[1]}"
    # Without the stub the two places are the same: no beam crosses anything in either.
    plain = LikelihoodField(twin_corridors(stub=False), sigma_hit=0.2, z_hit=0.5, z_rand=0.5, max_dist=2.0,
                            laser_max_range=RANGE)
    assert plain.through_walls(np.array([ROBOT, LOOK_ALIKE]), scan[ok], BEAMS[ok]).tolist() == [0, 0]
    # Without a margin the beam's end falls in the wall it hit: the margin is what keeps that out.
    assert field.through_walls(np.array([ROBOT]), scan[ok], BEAMS[ok], margin=0.0)[0] > 0
    assert field.through_walls(np.empty((0, 3)), scan[ok], BEAMS[ok]).shape == (0,)


def _params(**kw):
    return corridor_params(RANGE, **kw)


def _first_scan_error(params, seed=3) -> tuple[float, bool]:
    """The search starts with 3 % of the particles at the robot and 97 % at the same spot in B
    (a look-alike that took the weight early, as on the Radish logs); one scan at the robot."""
    grid = twin_corridors()
    odom = noisy_odometry(np.array([ROBOT, ROBOT + [0.1, 0.0, 0.0]]), NOISE, seed=seed)
    pf = ParticleFilter(params, grid, seed=seed)
    pf.global_localization()
    spread = pf.rng.normal(size=(2000, 3)) * np.array([0.05, 0.05, 0.03])
    pf.particles = np.vstack([ROBOT + spread[:60], LOOK_ALIKE + spread[60:]])
    pf.update(odom[0], cast(grid, ROBOT, BEAMS, RANGE), BEAMS, scan_max=RANGE)
    return math.hypot(*(pf.estimate[:2] - ROBOT[:2])), pf.searching


def test_the_search_weighs_the_beams_through_walls_and_picks_the_robots_place():
    error, _ = _first_scan_error(_params(search_through_wall_nats=2.0))
    assert error < 0.2, f"with the count, the robot's corridor wins the first scan: {error:.2f} m off"


def test_without_the_count_the_look_alike_with_more_particles_wins():
    error, searching = _first_scan_error(_params(search_through_wall_nats=0.0))
    assert error > 2.5 and not searching, "the likelihood field alone cannot tell them apart: the search ends on B"


def test_tracking_from_a_known_pose_is_bit_identical_with_the_option_on():
    path = np.array([[0.8 + 0.1 * k, 1.1, 0.0] for k in range(20)])
    off, on = tracked_estimates(twin_corridors(), [_params(search_through_wall_nats=n) for n in (0.0, 2.0)], path, RANGE)
    assert np.array_equal(off, on)


@pytest.mark.parametrize("name, value, match", [
    ("search_through_wall_nats", -1.0, r"AmclParams.search_through_wall_nats must be a number in \[0.0, 1000000.0\], got -1.0"),
    ("search_through_wall_margin", float("nan"), r"AmclParams.search_through_wall_margin must be a number in \[0.0, 10.0\], got nan"),
])
def test_the_parameters_are_validated_by_name(name, value, match):
    with pytest.raises(ValueError, match=match):
        AmclParams.of({name: value}, "LocalizerConfig.filter_params")
