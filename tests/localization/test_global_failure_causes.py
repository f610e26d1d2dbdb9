"""``emos bench localize --global`` records why each missed trial missed (issue 36): the search
ended on a wrong place, it had not decided yet, or it found the place and lost it after."""
from __future__ import annotations

import numpy as np
import pytest

from emos.tools.bench.localize import FAILURE_CAUSES, _failure_cause

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
