"""The likelihood field's lookup: the distance to the nearest wall is interpolated between cell
centres (bilinear), so a scan's likelihood changes continuously with the pose inside a cell
instead of being one value per cell (the old nearest-cell lookup)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.localization.likelihood import LikelihoodField
from emos.actors.nav.maps import OccupancyGridMap

pytestmark = pytest.mark.unit

RES = 0.05


def _wall_map() -> OccupancyGridMap:
    """4 x 4 m, free, with one wall one cell thick whose cells' centres lie at x = 2.025 m."""
    data = np.zeros((80, 80), dtype=np.int8)
    data[:, 40] = 100
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def _field(interpolation: str | None = None) -> LikelihoodField:
    kw = {} if interpolation is None else {"interpolation": interpolation}
    return LikelihoodField(_wall_map(), sigma_hit=0.05, z_hit=0.95, z_rand=0.05, max_dist=2.0, laser_max_range=10.0, **kw)


def _scores(field: LikelihoodField, xs: np.ndarray) -> np.ndarray:
    """Log-likelihood of one beam straight ahead (+x, 1 m) from robots at (x, 2, 0)."""
    poses = np.column_stack([xs, np.full(len(xs), 2.0), np.zeros(len(xs))])
    return field.log_likelihood(poses, np.array([1.0]), np.array([0.0]))


def test_the_default_lookup_resolves_the_pose_inside_a_cell() -> None:
    # End points 1.0125 .. 1.0375 + 1 m: all inside the wall's neighbour cell (x in [1.95, 2.0)),
    # so nearest-cell lookup gives one value; the pose differs by up to 2.5 cm.
    xs = np.array([0.9525, 0.96, 0.97, 0.98, 0.99])
    s = _scores(_field(), xs)
    assert np.all(np.diff(s) > 1e-3), f"expected the score to rise towards the wall, got {s}"


def test_bilinear_peaks_where_the_end_point_is_on_the_wall_centre() -> None:
    xs = np.linspace(0.95, 1.10, 61)  # end points from 1.95 to 2.10 m, the wall's centre at 2.025
    s = _scores(_field("bilinear"), xs)
    best = float(xs[int(np.argmax(s))]) + 1.0
    assert abs(best - 2.025) <= 0.0026, f"peak at {best:.4f} m, expected the wall's centre 2.025 m"


def test_nearest_lookup_is_a_staircase_and_still_selectable() -> None:
    xs = np.array([0.9525, 0.96, 0.97, 0.98, 0.99])
    s = _scores(_field("nearest"), xs)
    assert np.allclose(s, s[0]), f"nearest-cell lookup: one value per cell, got {s}"


def test_end_points_off_the_map_score_the_cap_either_way() -> None:
    far = np.array([[-5.0, -5.0, 0.0]])
    for mode in ("bilinear", "nearest"):
        f = _field(mode)
        got = f.log_likelihood(far, np.array([1.0]), np.array([0.0]))[0]
        cap = math.log(0.95 * math.exp(-(2.0 ** 2) / (2 * 0.05 ** 2)) + 0.05 / 10.0)
        assert got == pytest.approx(cap), mode


def test_an_unknown_lookup_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="interpolation must be 'bilinear' or 'nearest'"):
        _field("cubic")


def test_bilinear_matches_the_textbook_formula_on_random_poses() -> None:
    """The vectorised lookup (one flat index, neighbours at +1, +W, +W+1) against the plain
    formula: d interpolated from the four cell centres around each end point (the cap off the
    map), then log(z_hit exp(-d^2 / 2 sigma^2) + z_rand / max_range), summed over the beams."""
    rng = np.random.default_rng(3)
    data = np.where(rng.random((60, 90)) < 0.02, 100, 0).astype(np.int8)  # not square, no symmetry
    grid = OccupancyGridMap(data=data, resolution=RES, origin=(-1.0, 0.5, 0.3))
    field = LikelihoodField(grid, sigma_hit=0.1, z_hit=0.9, z_rand=0.1, max_dist=0.5, laser_max_range=10.0)
    h, w = field.shape
    res = field.resolution
    poses = np.column_stack([rng.uniform(-0.5, w * res + 0.5, 300), rng.uniform(-0.5, h * res + 0.5, 300),
                             rng.uniform(-np.pi, np.pi, 300)])
    ranges, angles = rng.uniform(0.1, 3.0, 25), rng.uniform(-np.pi, np.pi, 25)
    got = field.log_likelihood(poses, ranges, angles, chunk=64)
    dp = field._dist_padded
    want = np.zeros(len(poses))
    for n, (x, y, t) in enumerate(field.to_map_frame(poses)):
        for r, a in zip(ranges, angles):
            fx = (x + r * np.cos(t + a)) / res + 0.5
            fy = (y + r * np.sin(t + a)) / res + 0.5
            i, j = int(np.floor(fx)), int(np.floor(fy))
            if 0 <= i <= w and 0 <= j <= h:
                tx, ty = fx - i, fy - j
                d = ((1 - ty) * ((1 - tx) * dp[j, i] + tx * dp[j, i + 1]) + ty * ((1 - tx) * dp[j + 1, i] + tx * dp[j + 1, i + 1]))
            else:
                d = field._max_dist
            want[n] += np.log(field._z_hit * np.exp(-d * d * field._inv_2s2) + field._rand)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
