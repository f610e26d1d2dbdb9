"""The matcher's sub-cell polish: the bicubic squared-distance polish (``polish="distance"``) is
unbiased on exact data where the bilinear one snaps a wall's hits to the lattice; its trimming
and the submap densification it relies on."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.mapping.slam import CorrelativeMatcher, LikelihoodGrid
from emos.actors.nav.mapping.slam.matcher import _bicubic
from emos.actors.nav.mapping.slam.slam import densify, relative_pose

from .test_slam import ANGLES, _cast, _points, _room

pytestmark = pytest.mark.unit


def test_bicubic_interpolation_reproduces_a_quadratic_and_its_gradient() -> None:
    """Keys' cubic is exact for degree two: the property that puts a wall's crest where the wall is."""
    rows, cols = np.mgrid[0:12, 0:14].astype(float)

    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 0.7 * (x - 5.3) ** 2 + 0.2 * (x - 5.3) * (y - 6.1) + 1.3 * (y - 6.1) ** 2 + 0.4 * x

    table = f(cols, rows)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(2.0, 10.0, 50), rng.uniform(2.0, 9.0, 50)
    val, gx, gy = _bicubic(table, x, y)
    np.testing.assert_allclose(val, f(x, y), atol=1e-9)
    np.testing.assert_allclose(gx, 1.4 * (x - 5.3) + 0.2 * (y - 6.1) + 0.4, atol=1e-9)
    np.testing.assert_allclose(gy, 0.2 * (x - 5.3) + 2.6 * (y - 6.1), atol=1e-9)


def _self_match_errors(polish: str, gap: float) -> np.ndarray:
    """Exact scans matched against a grid of themselves, the scene shifted by sub-cell amounts
    against the lattice (a wall parallel to the grid falls anywhere between two cell rows);
    returns each match's position error (m)."""
    room = _room()
    errors = []
    for dx in np.arange(0.0, 0.05, 0.01):
        for dy in np.arange(0.0, 0.05, 0.0125):
            truth = np.array([6.0 + dx, 4.5 + dy, 0.3])
            pts = _points(_cast(room, truth, ANGLES), ANGLES)
            c, s = math.cos(truth[2]), math.sin(truth[2])
            world = np.column_stack([c * pts[:, 0] - s * pts[:, 1] + truth[0], s * pts[:, 0] + c * pts[:, 1] + truth[1]])
            grid = LikelihoodGrid(0.05, 0.05)
            grid.insert(densify(world, gap, 0.025))
            m = CorrelativeMatcher(polish=polish).match(grid, truth + [0.07, -0.04, 0.02], pts, window_xy=0.3,
                                                        window_theta=0.1)
            assert m is not None
            e = relative_pose(truth, m.pose)
            errors.append(math.hypot(e[0], e[1]))
    return np.array(errors)


def test_distance_polish_lands_within_5_mm_on_exact_data_where_the_bilinear_one_is_biased() -> None:
    bilinear = _self_match_errors("bilinear", 0.3)
    distance = _self_match_errors("distance", 0.3)
    assert bilinear.max() > 0.01, bilinear  # the bias: a continuous wall snaps to a row of cell centres
    assert distance.max() < 0.005 and distance.mean() < 0.0025, distance


def test_trimmed_polish_scores_every_hit() -> None:
    """Hits the grid has not seen are left out of the polish, not out of the score: a scan of
    which half is new must not look like a perfect match (loop closure acceptance reads it)."""
    room = _room()
    truth = np.array([6.0, 4.5, 0.0])
    pts = _points(_cast(room, truth, ANGLES), ANGLES)
    known = pts[pts[:, 1] >= 0]  # the grid saw only the left half of the scan
    grid = LikelihoodGrid(0.05, 0.05)
    grid.insert(densify(known + truth[:2], 0.3, 0.025))
    trimmed = CorrelativeMatcher(polish="distance", polish_trim=1.0).match(grid, truth, pts, window_xy=0.2,
                                                                            window_theta=0.05)
    assert trimmed is not None
    share = len(known) / len(pts)
    assert trimmed.score < share + 0.1, (trimmed.score, share)
    e = relative_pose(truth, trimmed.pose)
    assert math.hypot(e[0], e[1]) < 0.01, e


def test_densify_fills_a_surface_but_not_a_jump() -> None:
    pts = np.array([[0.0, 0.0], [0.1, 0.0], [1.0, 0.0], [1.06, 0.0]])
    out = densify(pts, 0.3, 0.025)
    np.testing.assert_allclose(out[:4], pts)  # the hits first, unchanged
    added = out[4:]
    assert len(added) == 3 + 2
    assert np.all(((added[:, 0] > 0) & (added[:, 0] < 0.1)) | ((added[:, 0] > 1.0) & (added[:, 0] < 1.06)))
    assert len(densify(pts[:1], 0.3, 0.025)) == 1
    np.testing.assert_array_equal(densify(pts, 0.0, 0.025), pts)
