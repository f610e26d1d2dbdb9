"""Global localization's search (issue 36): the full particle budget is kept while more than one
hypothesis holds weight, near-symmetric hypotheses are told apart by matching each one's scan
to its likelihood peak, the search ends (and tracking resumes, untempered) once one hypothesis
holds ``converged_weight``, and tracking from a known pose never enters it. The new parameters
are validated with errors that name them. Seeded, no processes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, ParticleFilter, noisy_odometry
from emos.actors.nav.maps import OccupancyGridMap
from tests.localization.helpers import BEAMS, MAX_RANGE, RES, cast, loop_path, room_map

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)


def _params(**kw):
    base = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=90, sigma_hit=0.2,
                laser_max_range=MAX_RANGE, update_min_d=0.1, update_min_a=0.1, min_particles=500,
                max_particles=3000, min_ess_fraction=0.0, search_min_ess_fraction=0.5,
                # The rules under test here, alone: no travel before the search may end, no
                # proposals (test_global_proposals.py tests those).
                converged_travel=0.0, search_candidates=0)
    base.update(kw)
    return AmclParams(**base)


def symmetric_room() -> OccupancyGridMap:
    """A 10 m x 8 m room that looks the same turned by 180 degrees about its centre, but for a
    small post (0.25 m square) near one corner: two places match almost every beam."""
    rows, cols = int(8.0 / RES), int(10.0 / RES)
    data = np.zeros((rows, cols), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    for x0, y0, x1, y1 in [(2.0, 2.0, 3.0, 2.6), (7.5, 1.0, 8.7, 1.4)]:
        for bx0, by0, bx1, by1 in [(x0, y0, x1, y1), (10.0 - x1, 8.0 - y1, 10.0 - x0, 8.0 - y0)]:
            data[int(round(by0 / RES)):int(round(by1 / RES)), int(round(bx0 / RES)):int(round(bx1 / RES))] = 100
    data[int(6.6 / RES):int(6.85 / RES), int(8.6 / RES):int(8.85 / RES)] = 100  # the post
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def _global_run(params, grid, path, seed, scans):
    odom = noisy_odometry(path, NOISE, seed=seed)
    pf = ParticleFilter(params, grid, seed=seed)
    pf.global_localization()
    errors, counts, searching, shares = [], [], [], []
    for i in range(scans):
        pf.update(odom[i], cast(grid, path[i]), BEAMS, scan_max=MAX_RANGE)
        errors.append(math.hypot(*(pf.estimate[:2] - path[i, :2])))
        counts.append(pf.particle_count)
        searching.append(pf.searching)
        shares.append(pf.hypothesis_shares.copy())
    return pf, np.array(errors), counts, searching, shares


def test_the_search_keeps_every_particle_until_one_hypothesis_dominates_then_tracks():
    grid, path = room_map(), loop_path()
    pf, errors, counts, searching, _ = _global_run(_params(max_beams=60), grid, path, seed=3, scans=40)
    end = searching.index(False)  # the search ended ...
    assert all(c == 3000 for c in counts[:end]), "while searching: the whole budget, no KLD shrinking"
    assert not any(searching[end:]), "... for good"
    assert counts[-1] < 2000, "then KLD sizes the converged cloud"
    assert pf.beta == 1.0, "tracking after the search: untempered (min_ess_fraction 0)"
    assert errors[end:].max() < 0.2 and errors[-10:].max() < 0.1


def test_near_symmetric_places_are_told_apart_by_their_scan_matched_peaks():
    """Half the particles at the robot, half at the place that looks the same but for the post
    (the room turned by 180 degrees): one scan. Tempered as the search tempers, the scan barely
    moves the weight (each place's particles sample its peak too coarsely to compare); the
    hypothesis check matches each place to its peak, finds the post only at the robot, puts
    the weight there and ends the search."""
    grid = symmetric_room()
    truth = np.array([8.0, 6.4, 0.3])      # the post 0.7 m ahead, on the left
    mirror = np.array([10.0 - truth[0], 8.0 - truth[1], truth[2] - math.pi])
    shares = {}
    for beta in (0.0, 0.2):
        # One scan: the check, not the convergence rule (converged_updates), is under test.
        pf = ParticleFilter(_params(hypothesis_beta=beta, max_particles=2000, converged_updates=1), grid, seed=5)
        pf.global_localization()
        spread = pf.rng.normal(size=(2000, 3)) * np.array([0.1, 0.1, 0.05])
        pf.particles = np.vstack([truth + spread[:1000], mirror + spread[1000:]])
        pf.update(truth, cast(grid, truth), BEAMS, scan_max=MAX_RANGE)
        shares[beta] = pf.hypothesis_shares[:2]
        if beta == 0.0:
            assert pf.searching and shares[beta].min() > 0.1, f"tempered alone: both places keep weight ({shares[beta]})"
        else:
            assert not pf.searching and shares[beta].max() > 0.95, f"checked: one place ({shares[beta]})"
            assert math.hypot(*(pf.estimate[:2] - truth[:2])) < 0.1, "... the robot's"


def test_tracking_from_a_known_pose_never_searches():
    grid, path = room_map(), loop_path()
    pf = ParticleFilter(_params(), grid, seed=4)
    pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
    odom = noisy_odometry(path, NOISE, seed=4)
    for i in range(20):
        pf.update(odom[i], cast(grid, path[i]), BEAMS, scan_max=MAX_RANGE)
        assert not pf.searching and len(pf.hypothesis_shares) == 0
    pf.global_localization()
    assert pf.searching, "the service call starts a search"
    pf.initialize(path[20])
    assert not pf.searching, "an initial pose ends it"


@pytest.mark.parametrize("name, value, match", [
    ("converged_weight", 0.3, r"AmclParams.converged_weight must be a number in \[0.5, 1.0\], got 0.3"),
    ("hypothesis_beta", float("nan"), r"AmclParams.hypothesis_beta must be a number in \[0.0, 10.0\], got nan"),
    ("max_hypotheses", 0, r"AmclParams.max_hypotheses must be an integer in \[1, 1000\], got 0"),
    ("max_hypotheses", 2.5, r"AmclParams.max_hypotheses must be an integer in \[1, 1000\], got 2.5"),
    ("search_min_ess_fraction", 1.5, r"AmclParams.search_min_ess_fraction must be a number in \[0.0, 1.0\], got 1.5"),
])
def test_new_parameters_are_validated_with_errors_that_name_them(name, value, match):
    with pytest.raises(ValueError, match=match):
        AmclParams.of({name: value}, "LocalizerConfig.filter_params")


def test_one_scan_of_a_look_alike_does_not_end_the_search():
    """The search ends only after the same hypothesis (carried by the odometry) has held
    ``converged_weight`` on ``converged_updates`` consecutive updates: one view of the robot's
    place, told apart by the post, leaves the search running; two more views along the way end
    it there."""
    grid = symmetric_room()
    truth = np.array([8.0, 6.4, 0.3])
    mirror = np.array([10.0 - truth[0], 8.0 - truth[1], truth[2] - math.pi])
    pf = ParticleFilter(_params(max_particles=2000, converged_updates=3, update_min_d=0.05), grid, seed=5)
    pf.global_localization()
    spread = pf.rng.normal(size=(2000, 3)) * np.array([0.1, 0.1, 0.05])
    pf.particles = np.vstack([truth + spread[:1000], mirror + spread[1000:]])
    path = [truth + np.array([-0.1 * k * math.cos(0.3), -0.1 * k * math.sin(0.3), 0.0]) for k in range(3)]
    held = []
    for pose in path:
        pf.update(pose, cast(grid, pose), BEAMS, scan_max=MAX_RANGE)
        held.append((pf.searching, pf.leader_updates, float(pf.hypothesis_shares.max())))
    assert held[0][0] and held[0][1] == 1 and held[0][2] > 0.95, f"one view: still searching ({held[0]})"
    assert held[1][0] and held[1][1] == 2, f"two views: still searching ({held[1]})"
    assert not held[2][0], f"three consistent views end it ({held})"
    assert math.hypot(*(pf.estimate[:2] - path[-1][:2])) < 0.1, "... at the robot"


def test_a_leader_that_changes_place_starts_the_count_again():
    """The rule itself: a hypothesis that holds the weight but is not where the last leader,
    moved by the odometry, would be (another place took over) counts from one again; a step
    below ``converged_weight`` resets the count."""
    pf = ParticleFilter(_params(converged_updates=3), room_map(), seed=1)
    pf.global_localization()
    p = pf.params
    held = []
    for odom, lead, share in [((0.0, 0.0, 0.0), (2.0, 2.0, 0.0), 0.97),   # 1
                              ((0.3, 0.0, 0.0), (2.3, 2.0, 0.0), 0.97),   # 2: moved with the odometry
                              ((0.6, 0.0, 0.0), (6.0, 4.0, 0.0), 0.97),   # 1: another place
                              ((0.9, 0.0, 0.0), (6.3, 4.0, 0.0), 0.90),   # 0: below converged_weight
                              ((1.2, 0.0, 0.0), (6.6, 4.0, 0.0), 0.97),   # 1
                              ((1.5, 0.0, 0.0), (6.9, 4.0, 0.1), 0.97),   # 2
                              ((1.8, 0.0, 0.0), (7.2, 4.0, 0.1), 0.97)]:  # 3: holds
        pf._odom_updated = np.array(odom)
        done = pf._leader_holds(np.array([share, 1.0 - share]), np.array([lead, (0.0, 0.0, 0.0)]), p)
        held.append((pf.leader_updates, done))
    assert held == [(1, False), (2, False), (1, False), (0, False), (1, False), (2, False), (3, True)], held


def test_converged_updates_is_validated_by_name():
    with pytest.raises(ValueError, match=r"AmclParams.converged_updates must be an integer in \[1, 1000\], got 0"):
        _params(converged_updates=0)


def test_the_leader_must_hold_over_travel_not_over_turns_on_the_spot():
    """``converged_travel``: a hypothesis that holds ``converged_weight`` while the robot turns
    on the spot (every update a view from the same place) does not end the search, however
    many updates it holds; driving ``converged_travel`` metres with it in the lead does. A
    change of leader starts the travel from zero again."""
    pf = ParticleFilter(_params(converged_travel=1.0), room_map(), seed=1)
    pf.global_localization()
    p = pf.params
    held = []
    steps = [((0.0, 0.0, 0.0), (2.0, 2.0, 0.0)),    # first view: 0 m
             ((0.0, 0.0, 0.3), (2.0, 2.0, 0.3)),    # turns on the spot: still 0 m
             ((0.0, 0.0, 0.6), (2.0, 2.0, 0.6)),
             ((0.0, 0.0, 0.9), (2.0, 2.0, 0.9)),
             ((0.0, 0.0, 0.0), (2.0, 2.0, 0.0)),
             ((0.6, 0.0, 0.0), (2.6, 2.0, 0.0)),    # drives 0.6 m with it
             ((0.9, 0.0, 0.0), (6.0, 5.0, 0.0)),    # another place takes the lead: from 0
             ((1.5, 0.0, 0.0), (6.6, 5.0, 0.0)),    # 0.6 m
             ((2.1, 0.0, 0.0), (7.2, 5.0, 0.0))]    # 1.2 m: holds
    for odom, lead in steps:
        pf._odom_updated = np.array(odom)
        done = pf._leader_holds(np.array([0.97, 0.03]), np.array([lead, (0.0, 0.0, 0.0)]), p)
        held.append((pf.leader_updates, round(pf.leader_travel, 2), done))
    assert [h[2] for h in held] == [False] * 8 + [True], held
    assert [h[1] for h in held] == [0.0, 0.0, 0.0, 0.0, 0.0, 0.6, 0.0, 0.6, 1.2], held
    assert held[4][0] == 5, "five consistent updates, none of them travel"


def test_converged_travel_is_validated_by_name():
    with pytest.raises(ValueError, match=r"AmclParams.converged_travel must be a number in \[0.0, 1000.0\], got -1"):
        _params(converged_travel=-1)
