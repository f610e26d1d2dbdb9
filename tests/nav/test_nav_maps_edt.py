"""Exact EDT against a brute-force reference, and inflation built on it."""
import numpy as np
import pytest

from emos.actors.nav.maps import (
    OccupancyGridMap,
    distance_map,
    euclidean_distance_transform,
    inflate,
    squared_distance_transform_1d,
)

pytestmark = pytest.mark.unit


def brute_force_edt(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return np.full(mask.shape, np.inf)
    yy, xx = np.indices(mask.shape)
    d2 = (yy[..., None] - ys) ** 2 + (xx[..., None] - xs) ** 2
    return np.sqrt(d2.min(axis=-1))


@pytest.fixture(params=["scipy", "numpy"])
def backend(request, monkeypatch):
    """Both implementations: scipy's (used when installed) and the numpy fallback."""
    from emos.actors.nav.maps import edt

    if request.param == "numpy":
        monkeypatch.setattr(edt, "_scipy_ndimage", lambda: None)
    else:
        pytest.importorskip("scipy")
    return request.param


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("density", [0.005, 0.05, 0.3, 0.8])
def test_edt_matches_brute_force_on_random_grids(seed, density, backend):
    rng = np.random.default_rng(seed)
    shape = tuple(rng.integers(1, 45, size=2))
    mask = rng.random(shape) < density
    got = euclidean_distance_transform(mask, sampling=0.05)
    want = brute_force_edt(mask) * 0.05
    assert got.shape == mask.shape
    assert np.array_equal(np.isinf(got), np.isinf(want))
    finite = np.isfinite(want)
    np.testing.assert_allclose(got[finite], want[finite], rtol=0, atol=1e-9)


def test_edt_edge_cases_and_sampling(backend):
    assert np.all(np.isinf(euclidean_distance_transform(np.zeros((4, 5), bool))))
    assert np.all(euclidean_distance_transform(np.ones((3, 3), bool)) == 0)
    mask = np.zeros((5, 7), bool)
    mask[2, 3] = True
    d = euclidean_distance_transform(mask, sampling=0.05)
    assert d[2, 3] == 0
    assert d[0, 0] == pytest.approx(0.05 * np.hypot(2, 3))
    with pytest.raises(ValueError, match="2D"):
        euclidean_distance_transform(np.zeros(5, bool))
    with pytest.raises(ValueError, match="sampling"):
        euclidean_distance_transform(mask, sampling=0)


def test_1d_transform_is_lower_envelope_of_parabolas():
    f = np.array([[np.inf, 4.0, np.inf, 0.0, np.inf, np.inf, 1.0]])
    q = np.arange(7)
    want = np.min((q[:, None] - q[None, :]) ** 2 + f[0][None, :], axis=1)
    np.testing.assert_allclose(squared_distance_transform_1d(f)[0], want)


def test_inflation_marks_exactly_the_cells_within_radius():
    rng = np.random.default_rng(3)
    data = np.zeros((40, 30), np.int8)
    data[rng.random(data.shape) < 0.02] = 100
    data[0:3, 0:3] = -1
    grid = OccupancyGridMap(data=data, resolution=0.1, origin=(1.0, 2.0, 0.3))
    out = inflate(grid, radius=0.25)
    ref = brute_force_edt(data >= 65) * 0.1
    expected = np.where(ref <= 0.25 + 1e-12, 100, data)
    assert np.array_equal(out.data, expected)
    # Same geometry, input untouched.
    assert out.resolution == grid.resolution and out.origin == grid.origin
    assert (grid.data == data).all()


def test_inflation_radius_zero_and_errors():
    grid = OccupancyGridMap(data=np.zeros((3, 3), np.int8), resolution=0.05)
    assert np.array_equal(inflate(grid, 0.0).data, grid.data)
    with pytest.raises(ValueError, match="radius"):
        inflate(grid, -1.0)


def test_distance_map_in_metres_and_unknown_option():
    data = np.zeros((10, 10), np.int8)
    data[5, 5] = 100
    data[0, 0] = -1
    grid = OccupancyGridMap(data=data, resolution=0.2)
    d = distance_map(grid)
    assert d[5, 8] == pytest.approx(0.6)
    assert d[0, 0] == pytest.approx(0.2 * np.hypot(5, 5))
    assert distance_map(grid, unknown_is_occupied=True)[0, 0] == 0.0


@pytest.mark.parametrize("seed", range(5))
def test_1d_transform_matches_brute_force_with_gaps(seed):
    rng = np.random.default_rng(100 + seed)
    f = rng.integers(0, 60, size=(37, 41)).astype(float)
    f[rng.random(f.shape) < 0.6] = np.inf
    f[3] = np.inf  # a line without any sample stays inf
    q = np.arange(f.shape[1])
    want = np.min((q[:, None] - q[None, :])[None] ** 2 + f[:, None, :], axis=2)
    got = squared_distance_transform_1d(f)
    assert np.array_equal(got, want)
