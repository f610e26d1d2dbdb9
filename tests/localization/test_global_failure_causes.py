"""``emos bench localize --global`` records why each missed trial missed (issue 36): the search
ended on a wrong place, it had not decided yet, or it found the place and lost it after."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, ParticleFilter
from emos.tools.bench.localize import FAILURE_CAUSES, _failure_cause, _fits_at
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, room_map

pytestmark = pytest.mark.unit

MOVED = np.arange(0.0, 20.0, 1.0)  # one scan a metre, 10 m at scan 10
AFTER = MOVED >= 10.0
HEAD = np.zeros_like(MOVED)


def _pos(*segments: tuple[int, int, float]) -> np.ndarray:
    pos = np.full(len(MOVED), 0.05)
    for lo, hi, err in segments:
        pos[lo:hi] = err
    return pos


@pytest.mark.parametrize("pos, ended, cause", [
    (_pos((0, 4, 5.0)), 6, None),                     # found before 10 m
    (_pos((0, 12, 5.0)), 3, "wrong_place"),           # the search ended at scan 3 on a place 5 m off
    (_pos((0, 12, 5.0)), None, "undecided"),          # never ended
    (_pos((0, 12, 5.0)), 11, "undecided"),            # ended after 10 m
    (_pos((8, 20, 0.6)), 4, "lost"),                  # ended on the right place, off by 0.6 m at 10 m
    (_pos((0, 3, 5.0)), None, None),                  # right without ending the search: converged
])
def test_each_missed_trial_gets_its_cause(pos, ended, cause):
    assert _failure_cause(pos, HEAD, MOVED, AFTER, ended) == cause
    assert cause is None or cause in FAILURE_CAUSES


def test_a_trial_too_short_to_reach_the_convergence_travel_is_undecided():
    assert _failure_cause(_pos(), HEAD, MOVED, np.zeros(len(MOVED), dtype=bool), 2) == "undecided"


def test_a_miss_records_how_well_the_scan_fits_near_the_logged_pose_and_near_the_estimate():
    """A missed trial records the scan's fit (mean log-likelihood per beam at the nearest peak)
    near the logged pose and near the wrong estimate: the scan taken at the logged pose fits
    best there, so a miss whose estimate fits better is one the scan cannot tell apart."""
    grid = room_map()
    truth = np.array([4.0, 4.0, 0.3])
    wrong = np.array([6.0, 3.0, 2.0])
    data = {"ranges": [cast(grid, truth)], "angles": [BEAMS], "max_range": MAX_RANGE}
    pf = ParticleFilter(AmclParams(laser_max_range=MAX_RANGE, sigma_hit=0.2), grid, seed=0)
    near_truth, near_wrong = _fits_at(pf, data, 0, truth + np.array([0.1, -0.1, 0.05]), wrong)
    assert near_truth > near_wrong + 0.5, (near_truth, near_wrong)
    assert near_truth > -1.0, "a perfect scan at its own pose: near the best per-beam value"
    empty = {"ranges": [np.full(len(BEAMS), np.nan)], "angles": [BEAMS], "max_range": MAX_RANGE}
    assert all(np.isnan(_fits_at(pf, empty, 0, truth, wrong))), "no valid beam: no fit, no crash"
