"""Scan-match factors' covariance from the match itself (issue 36): the least-squares
covariance at the polished optimum (inverse curvature of the matching cost) is long along a
featureless corridor and short across it, sharp in a room, and is what the SLAM puts on its
factors when ``factor_covariance="hessian"`` (scaled by ``hessian_cov_scale``)."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.mapping.slam import CorrelativeMatcher, GraphSlam, SlamParams
from tests.slam.test_slam import ANGLES, _cast, _grid_from, _points, _room

pytestmark = pytest.mark.unit


def test_hessian_covariance_is_long_along_a_corridor_and_short_across() -> None:
    corridor = np.array([(-50, 0, 50, 0), (-50, 2, 50, 2)], dtype=float)
    truth = np.array([0.0, 1.0, 0.0])
    # A submap of scans taken along the corridor (not at the scan's own pose: its hits would
    # sit exactly on the map's).
    grid = _grid_from(corridor, [np.array([x, 1.0, 0.0]) for x in (-2.0, -1.37, -0.71, 0.33, 1.1, 2.2, 3.1)])
    scan = _points(_cast(corridor, truth, ANGLES, 8.0), ANGLES, 8.0)  # a short-range scanner sees no end
    m = CorrelativeMatcher().match(grid, truth + [0.2, 0.05, 0.02], scan, window_xy=0.6, window_theta=0.1)
    assert m is not None
    c = m.hessian_covariance
    # Across the corridor the walls fix the pose to millimetres; along it only the field's
    # small bumps between far hits say anything: ten times the standard deviation.
    assert math.sqrt(c[1, 1]) < 0.01, c
    assert c[0, 0] > 25 * c[1, 1], c


def test_hessian_covariance_is_sharp_in_a_room_and_grows_with_the_misfit() -> None:
    room = _room()
    truth = np.array([6.0, 4.5, 0.3])
    grid = _grid_from(room, [truth])
    scan = _points(_cast(room, truth, ANGLES), ANGLES)
    m = CorrelativeMatcher().match(grid, truth + [0.1, -0.1, 0.05], scan, window_xy=0.5, window_theta=0.2)
    assert m is not None
    sharp = m.hessian_covariance
    assert np.sqrt(np.linalg.eigvalsh(sharp[:2, :2]).max()) < 0.01, sharp
    # The same scan with 3 cm of range noise fits the map worse: a wider covariance.
    rng = np.random.default_rng(0)
    noisy = scan + rng.normal(0.0, 0.03, scan.shape)
    m2 = CorrelativeMatcher().match(grid, truth, noisy, window_xy=0.5, window_theta=0.2)
    assert m2 is not None
    assert np.trace(m2.hessian_covariance[:2, :2]) > 1.3 * np.trace(sharp[:2, :2])


def _factor_covariances(kind: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Run 4 scans of the room through the SLAM; the covariance of every between factor it
    added, and the scaled-and-rotated Hessian covariance of every match it made."""
    room = _room()
    slam = GraphSlam(SlamParams(factor_covariance=kind, hessian_cov_scale=7.0))
    factors: list[np.ndarray] = []
    expected: list[np.ndarray] = []
    add = slam.graph.add_between

    def record_factor(a, b, measured, cov, loop=False):
        factors.append(np.asarray(cov))
        add(a, b, measured, cov, loop=loop)

    class Recording(CorrelativeMatcher):
        def match(self, *args, **kwargs):
            m = super().match(*args, **kwargs)
            if m is not None:
                c, s = math.cos(m.pose[2]), math.sin(m.pose[2])
                rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # grid axes -> the node's
                expected.append(7.0 * rot @ m.hessian_covariance @ rot.T)
            return m

    slam.graph.add_between = record_factor
    slam.matcher = Recording()
    for k in range(4):
        pose = np.array([6.0 + 0.2 * k, 4.5, 0.05 * k])
        slam.add(pose, _cast(room, pose, ANGLES), ANGLES)
    return factors, expected


def test_the_slam_puts_the_scaled_hessian_covariance_on_its_match_factors() -> None:
    factors, expected = _factor_covariances("hessian")
    assert len(expected) == 3  # scans 1..3 matched against the submap
    for cov in expected:
        assert any(np.allclose(f, cov) for f in factors)
    # The default (the response's spread, scaled by match_cov_scale) is another covariance.
    factors, expected = _factor_covariances("response")
    assert not any(np.allclose(f, cov) for f in factors for cov in expected)
