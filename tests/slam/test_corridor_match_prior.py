"""The front end's prior towards the odometry guess only breaks ties (issue 36): along a corridor
the few hits on a far end wall fix the position along it, and the default ``prior_weight`` must
let them win over an odometry guess two of its standard deviations off (on aces the stronger
old prior, 0.05, followed the odometry's error along the corridors)."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.mapping.slam import CorrelativeMatcher, LikelihoodGrid, SlamParams
from emos.actors.nav.mapping.slam.matcher import voxel_filter
from tests.slam.test_slam import _cast, _points

pytestmark = pytest.mark.unit

ANGLES = np.linspace(-math.pi / 2, math.pi / 2, 181)
RANGE = 30.0
# A 2 m corridor, 50 m long, closed by an end wall 20 m ahead of the scan: along the corridor
# only the end wall's few hits (about 6 of 110 after the voxel filter) say where the scan is.
CORRIDOR = np.array([(-30, -1, 20, -1), (-30, 1, 20, 1), (20, -1, 20, 1)], dtype=float)


def _submap(poses: list[np.ndarray]) -> LikelihoodGrid:
    grid = LikelihoodGrid(0.05, 0.05, margin=5.0)
    for pose in poses:
        pts = _points(_cast(CORRIDOR, pose, ANGLES, RANGE), ANGLES, RANGE)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        grid.insert(np.column_stack([c * pts[:, 0] - s * pts[:, 1] + pose[0], s * pts[:, 0] + c * pts[:, 1] + pose[1]]))
    return grid


@pytest.mark.parametrize("offset", [0.25, -0.25])
def test_a_far_end_wall_beats_the_odometry_guess_along_a_corridor(offset: float) -> None:
    truth = np.array([0.0, 0.1, 0.0])
    # The submap: the scans before, about 0.8 m apart, slightly weaving (not the scan's own pose).
    grid = _submap([np.array([x, 0.1 + 0.05 * math.sin(x), 0.02 * math.cos(3 * x)]) for x in np.arange(-9.5, -0.3, 0.83)])
    scan = voxel_filter(_points(_cast(CORRIDOR, truth, ANGLES, RANGE), ANGLES, RANGE), SlamParams().voxel)
    sd_along = 0.13  # the odometry's standard deviation for a 0.9 m step (the SLAM's alphas on the benchmark)
    guess = truth + np.array([2 * sd_along * math.copysign(1.0, offset), 0.02, 0.01])
    m = CorrelativeMatcher().match(grid, guess, scan, window_xy=3 * sd_along, window_theta=math.radians(6.0),
                                   prior_weight=SlamParams().prior_weight, prior_sigma=(sd_along, 0.02))
    assert m is not None
    # The end wall puts the scan within 3 cm of the truth along the corridor (the old prior kept
    # it 0.2 m off, at the guess's side).
    assert abs(m.pose[0] - truth[0]) < 0.03, m.pose
    assert abs(m.pose[1] - truth[1]) < 0.04 and abs(m.pose[2]) < math.radians(0.5), m.pose


def test_the_match_covariance_can_leave_the_prior_out() -> None:
    """The prior towards the guess is the odometry, which the pose graph holds as a factor of its
    own. With ``cov_with_prior=False`` the response covariance is the scan's alone: along a
    corridor whose end is out of reach it is as long as the neighbourhood it is taken over,
    where the default's (with the prior in it) is short."""
    corridor = np.array([(-50, -1, 50, -1), (-50, 1, 50, 1)], dtype=float)
    truth = np.array([0.0, 0.1, 0.0])
    grid = LikelihoodGrid(0.05, 0.05, margin=5.0)
    for x in np.arange(-6.0, -0.3, 0.83):
        pose = np.array([x, 0.1 + 0.05 * math.sin(x), 0.0])
        pts = _points(_cast(corridor, pose, ANGLES, 8.0), ANGLES, 8.0)
        grid.insert(pts + pose[:2])
    scan = voxel_filter(_points(_cast(corridor, truth, ANGLES, 8.0), ANGLES, 8.0), SlamParams().voxel)
    kw = dict(window_xy=0.4, window_theta=math.radians(4.0), prior_sigma=(0.05, 0.02))
    guess = truth + np.array([0.05, 0.0, 0.0])
    with_prior = CorrelativeMatcher().match(grid, guess, scan, prior_weight=1.0, **kw)
    own = CorrelativeMatcher(cov_with_prior=False).match(grid, guess, scan, prior_weight=1.0, **kw)
    assert with_prior is not None and own is not None
    # The same pose (the prior decides along the corridor) ...
    np.testing.assert_allclose(own.pose, with_prior.pose)
    # ... but along the corridor the scan itself says nothing: its own spread there is as wide
    # as the covariance neighbourhood (+-6 cells), the prior's is a tenth of that.
    assert math.sqrt(own.covariance[0, 0]) > 0.1, own.covariance
    assert own.covariance[0, 0] > 20.0 * with_prior.covariance[0, 0], (own.covariance, with_prior.covariance)
    # Across it the walls decide.
    assert own.covariance[1, 1] < own.covariance[0, 0] / 10.0, own.covariance
