"""Runner-up hypotheses after a global search (issue 36, ``runner_up_nats``): the search can end
on a look-alike place after one view; the places that fitted that view about as well are kept
(a few hundred particles each, compared with the leader on every scan by their scan-matched
peaks), so when a later scan tells them apart the filter switches to the right one. Seeded, no
processes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, ParticleFilter, noisy_odometry
from emos.actors.nav.maps import OccupancyGridMap
from tests.localization.helpers import BEAMS, cast, corridor_params, tracked_estimates
from tests.localization.helpers import twin_corridors as corridors

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)
RANGE = 3.0  # a short-range scanner: the far end of a corridor is out of sight from its start


def twin_corridors() -> OccupancyGridMap:
    """The helpers' twin corridors with a cabinet on A's north wall at x 7.5-8.5. From the west
    end, 3 m of range sees the same walls in both; only from x > 4.5 does the cabinet show which
    corridor it is."""
    return corridors(((7.5, 1.5, 8.5, 2.1),))


def _params(**kw):
    return corridor_params(RANGE, **kw)


def _drive(params, seed=3):
    """The robot drives east along A from its west end; the search starts with 3 % of the
    particles at the robot and 97 % at the same spot in B (a look-alike that took the weight
    early, as on the Radish logs). The first scan ends the search on B."""
    grid = twin_corridors()
    path = np.array([[0.8 + 0.1 * k, 1.0, 0.0] for k in range(90)])
    odom = noisy_odometry(path, NOISE, seed=seed)
    pf = ParticleFilter(params, grid, seed=seed)
    pf.global_localization()
    spread = pf.rng.normal(size=(2000, 3)) * np.array([0.05, 0.05, 0.03])
    pf.particles = np.vstack([path[0] + spread[:60], path[0] + np.array([0.0, 3.0, 0.0]) + spread[60:]])
    errors, runner_ups = [], []
    for i in range(len(path)):
        pf.update(odom[i], cast(grid, path[i], BEAMS, RANGE), BEAMS, scan_max=RANGE)
        errors.append(math.hypot(*(pf.estimate[:2] - path[i, :2])))
        runner_ups.append(len(pf.runner_ups))
        if i == 0:
            assert not pf.searching and pf.hypothesis_shares.max() > 0.95, "one view ends the search"
            assert errors[0] > 2.5, "... on the look-alike corridor"
    return pf, np.array(errors), runner_ups


def test_a_kept_runner_up_takes_over_when_a_later_scan_tells_the_places_apart():
    pf, errors, runner_ups = _drive(_params(runner_up_nats=60.0))
    assert runner_ups[0] == 1, "the right corridor fitted the first view as well: kept"
    assert pf.switches == 1, "one switch, to the right corridor, and no switching back"
    assert errors[-20:].max() < 0.2, f"it ends on the robot (last errors {errors[-5:]})"
    first_right = int(np.flatnonzero(errors < 0.2)[0])
    assert 0.8 + 0.1 * first_right > 4.5, "not before the cabinet could be seen"
    assert runner_ups[-1] == 0, "the look-alike, now trailing, was dropped"


def test_without_runner_ups_the_search_keeps_the_look_alike():
    """The old behaviour (``runner_up_nats`` 0, off): the other places are dropped when the
    search ends, and the filter follows the wrong corridor to the end."""
    pf, errors, runner_ups = _drive(_params(runner_up_nats=0.0))
    assert not any(runner_ups) and pf.switches == 0
    assert errors[-1] > 2.5


def test_runner_ups_never_exist_when_tracking_from_a_known_pose():
    grid = twin_corridors()
    path = np.array([[0.8 + 0.1 * k, 1.0, 0.0] for k in range(30)])
    odom = noisy_odometry(path, NOISE, seed=1)
    pf = ParticleFilter(_params(runner_up_nats=60.0), grid, seed=1)
    pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
    for i in range(len(path)):
        pf.update(odom[i], cast(grid, path[i], BEAMS, RANGE), BEAMS, scan_max=RANGE)
        assert not pf.runner_ups
    off, on = tracked_estimates(grid, [_params(runner_up_nats=n) for n in (0.0, 60.0)], path, RANGE)
    assert np.array_equal(off, on), "tracking is bit-identical with the option on"


@pytest.mark.parametrize("name, value, match", [
    ("runner_up_nats", -1.0, r"AmclParams.runner_up_nats must be a number in \[0.0, 1000000.0\], got -1.0"),
    ("runner_up_scan_nats", 0.0, r"AmclParams.runner_up_scan_nats must be a number in \(0.0, 1000000.0\], got 0.0"),
    ("runner_up_particles", 0, r"AmclParams.runner_up_particles must be an integer in \[1, 1000000\], got 0"),
])
def test_runner_up_parameters_are_validated_by_name(name, value, match):
    with pytest.raises(ValueError, match=match):
        AmclParams.of({name: value}, "LocalizerConfig.filter_params")
