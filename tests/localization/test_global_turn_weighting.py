"""Turn weighting during a global search (issue 36, ``search_turn_weight``): scans taken while the
robot turns on the spot can fit a look-alike better than the robot's true place for several scans
in a row (intel: 30 degrees between scans, the true place up to 190 nats worse), enough to take
all its particles before a scan taken while driving can tell the places apart. With the option,
such scans weigh little in the search, so the true place survives them. Seeded, no processes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization import AmclParams, ParticleFilter, noisy_odometry
from emos.actors.nav.maps import OccupancyGridMap
from tests.localization.helpers import RES, cast

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)
RANGE = 3.0
FRONT = np.linspace(-math.pi / 2, math.pi / 2, 91)  # a 180-degree scanner, as on the Radish robots
TURN = math.radians(30.0)  # per scan while turning on the spot, as on intel
LOOK_ALIKE = np.array([0.0, 3.0, 0.0])  # corridor B is corridor A moved 3 m north


def twin_corridors() -> OccupancyGridMap:
    """Two closed corridors, 12 m x 2 m, one above the other (A: y 0.1-2.1, B: y 3.1-5.1), the
    same but for a cabinet at x 7.5-8.5: on A's north wall, on B's south wall. A scan that
    shows one of them puts beam ends in the other corridor's free space: it tells them apart."""
    rows, cols = int(6.0 / RES), int(12.0 / RES)
    data = np.zeros((rows, cols), dtype=np.int8)

    def box(x0: float, y0: float, x1: float, y1: float) -> None:
        data[int(round(y0 / RES)):int(round(y1 / RES)), int(round(x0 / RES)):int(round(x1 / RES))] = 100

    for y in (0.0, 3.0):
        box(0.0, y, 12.0, y + 0.1)
        box(0.0, y + 2.1, 12.0, y + 2.2)
        box(0.0, y, 0.1, y + 2.2)
        box(11.9, y, 12.0, y + 2.2)
    box(7.5, 1.5, 8.5, 2.1)  # A's cabinet
    box(7.5, 3.1, 8.5, 3.7)  # B's
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def _params(**kw):
    base = dict(alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, max_beams=91, sigma_hit=0.2,
                laser_max_range=RANGE, update_min_d=0.1, update_min_a=0.1, min_particles=500, max_particles=2000,
                # On the Radish logs the tempering keeps 1-3 % of a scan's evidence (20000 particles
                # over the whole map), so the hypotheses' peak comparison moves the weight between
                # places; with two tight clouds here, 0.95 keeps it that way.
                search_min_ess_fraction=0.95, converged_travel=0.0, search_candidates=0)
    base.update(kw)
    return AmclParams(**base)


def _path() -> tuple[np.ndarray, np.ndarray]:
    """The robot stands in A at x 6.5 facing west (the cabinets behind it, out of view: A and B
    look the same), turns on the spot through south to face east, 30 degrees a scan, then
    drives east past the cabinet. Returns the poses and, per scan, whether it was taken while turning."""
    turn = [[6.5, 1.0, math.pi + TURN * k] for k in range(7)]
    drive = [[6.5 + 0.1 * k, 1.0, 0.0] for k in range(1, 31)]
    poses = np.array(turn + drive)
    poses[:, 2] = np.arctan2(np.sin(poses[:, 2]), np.cos(poses[:, 2]))
    return poses, np.array([0 < k < 7 for k in range(len(poses))])


def _search(params, seed=5):
    """The search starts with half the particles at the robot and half at the same spot in B.
    The scans taken while turning are what the scanner would see in B (B's cabinet, not A's): they fit the look-alike better than the robot's place, as intel's
    turn-on-the-spot scans do. The scans taken while driving are true."""
    grid = twin_corridors()
    path, turning = _path()
    odom = noisy_odometry(path, NOISE, seed=seed)
    pf = ParticleFilter(params, grid, seed=seed)
    pf.global_localization()
    spread = pf.rng.normal(size=(2000, 3)) * np.array([0.05, 0.05, 0.03])
    pf.particles = np.vstack([path[0] + spread[:1000], path[0] + LOOK_ALIKE + spread[1000:]])
    errors, weights = [], []
    for i in range(len(path)):
        seen_from = path[i] + LOOK_ALIKE if turning[i] else path[i]
        pf.update(odom[i], cast(grid, seen_from, FRONT, RANGE), FRONT, scan_max=RANGE)
        errors.append(math.hypot(*(pf.estimate[:2] - path[i, :2])))
        weights.append(pf.turn_weight)
    return pf, np.array(errors), np.array(weights), turning


def test_scans_taken_while_turning_no_longer_wipe_out_the_true_place():
    pf, errors, weights, turning = _search(_params(search_turn_weight=0.0, search_turn_angle=0.4))
    assert np.all(weights[turning] == 0.0), "30 degrees a scan is past search_turn_angle: no weight"
    assert not pf.searching, "the scans taken while driving ended the search"
    assert errors[-10:].max() < 0.5 and errors[-1] < 0.2, f"on the robot's corridor (last errors {errors[-5:]})"


def test_without_turn_weighting_the_turning_scans_decide_for_the_look_alike():
    """The old behaviour (``search_turn_weight`` 1, off): the turning scans take the true place's
    particles, and the filter follows the wrong corridor to the end."""
    pf, errors, weights, _ = _search(_params(search_turn_weight=1.0))
    assert np.all(weights == 1.0)
    assert errors[-1] > 2.5, f"in the look-alike corridor, 3 m off (last errors {errors[-5:]})"


def test_the_weight_falls_linearly_with_the_turn_between_two_scans():
    pf = ParticleFilter(_params(search_turn_weight=0.2, search_turn_angle=0.4), twin_corridors(), seed=1)
    for turn, expected in [(0.0, 1.0), (0.1, 0.8), (0.2, 0.6), (0.4, 0.2), (1.0, 0.2)]:
        pf._turn = turn
        assert pf._turn_weight() == pytest.approx(expected)


def test_tracking_from_a_known_pose_is_bit_identical_with_the_option_on():
    grid = twin_corridors()
    path, _ = _path()
    odom = noisy_odometry(path, NOISE, seed=2)
    tracked = []
    for weight in (1.0, 0.0):
        pf = ParticleFilter(_params(search_turn_weight=weight), grid, seed=2)
        pf.initialize(path[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.03 ** 2]))
        for i in range(len(path)):
            pf.update(odom[i], cast(grid, path[i], FRONT, RANGE), FRONT, scan_max=RANGE)
            assert pf.turn_weight == 1.0
        tracked.append((pf.estimate.copy(), pf.particles.copy()))
    assert np.array_equal(tracked[0][0], tracked[1][0]) and np.array_equal(tracked[0][1], tracked[1][1])


@pytest.mark.parametrize("name, value, match", [
    ("search_turn_weight", -0.1, r"AmclParams.search_turn_weight must be a number in \[0.0, 1.0\], got -0.1"),
    ("search_turn_weight", 1.5, r"AmclParams.search_turn_weight must be a number in \[0.0, 1.0\], got 1.5"),
    ("search_turn_weight", float("nan"), r"AmclParams.search_turn_weight must be a number in \[0.0, 1.0\], got nan"),
    ("search_turn_angle", 0.0, r"AmclParams.search_turn_angle must be a number in \(0.0, 6.28"),
    ("search_turn_angle", "fast", r"AmclParams.search_turn_angle must be a number in \(0.0, 6.28"),
])
def test_turn_weighting_parameters_are_validated_by_name(name, value, match):
    with pytest.raises(ValueError, match=match):
        AmclParams.of({name: value}, "LocalizerConfig.filter_params")
