"""The simple smoother: smooths a staircase, keeps the ends, never moves a point into
inscribed or lethal cost."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.costmap import Costmap2D, CostmapConfig, LayeredCostmap, SmootherConfig, smooth_path
from emos.actors.nav.maps import OccupancyGridMap

pytestmark = pytest.mark.unit


def _staircase() -> np.ndarray:
    xy = [(0.5 + 0.05 * i, 0.5 + 0.05 * (i // 4)) for i in range(60)]
    return np.column_stack([np.asarray(xy), np.zeros(len(xy))])


def _turn_rms(path: np.ndarray) -> float:
    heading = np.arctan2(np.diff(path[:, 1]), np.diff(path[:, 0]))
    return float(np.sqrt(np.mean(np.diff(heading) ** 2)))


def test_smoother_reduces_turning_and_keeps_the_ends():
    raw = _staircase()
    out = smooth_path(raw, SmootherConfig(enabled=True))
    assert np.allclose(out[0, :2], raw[0, :2]) and np.allclose(out[-1, :2], raw[-1, :2])
    assert _turn_rms(out) < 0.5 * _turn_rms(raw)
    assert np.max(np.hypot(*(out[:, :2] - raw[:, :2]).T)) < 0.1  # w_data keeps it near the plan


def test_smoothed_points_never_enter_inscribed_or_lethal_cost():
    # A corner path hugging an obstacle: smoothing would cut the corner through it.
    data = np.zeros((60, 60), dtype=np.int8)
    data[20:40, 20:40] = 100
    grid = OccupancyGridMap(data=data, resolution=0.05)
    costmap = LayeredCostmap(CostmapConfig(enabled=True, inflation_radius=0.3, cost_scaling_factor=5.0), 0.1)
    master = costmap.set_map(grid)
    corner = [(0.8 + 0.05 * i, 0.8) for i in range(25)] + [(2.05, 0.8 + 0.05 * i) for i in range(1, 25)]
    # Inside the square's inscribed band at the corner: a path the planner accepts hugs it.
    raw = np.column_stack([np.asarray(corner), np.zeros(len(corner))])
    free = master.cost_at(raw[:, :2]) < 253
    unchecked = smooth_path(raw, SmootherConfig(enabled=True, w_smooth=0.45, w_data=0.01))
    assert np.any((master.cost_at(unchecked[:, :2]) >= 253) & free), "the test path must be one smoothing would cut"
    checked = smooth_path(raw, SmootherConfig(enabled=True, w_smooth=0.45, w_data=0.01), master)
    cost = master.cost_at(checked[:, :2])
    assert not np.any((cost >= 253) & free)  # no point moved into collision
    assert np.any(np.hypot(*(checked[:, :2] - raw[:, :2]).T) > 1e-3)  # the free stretches were still smoothed


def test_smoother_rejects_bad_paths_and_parameters():
    with pytest.raises(ValueError, match="finite poses"):
        smooth_path(np.array([[0.0, np.nan], [1.0, 1.0], [2.0, 2.0]]), SmootherConfig())
    with pytest.raises(ValueError, match="w_smooth"):
        SmootherConfig(w_smooth=0.9)
    assert len(smooth_path(np.zeros((2, 3)), SmootherConfig(), Costmap2D(OccupancyGridMap(data=np.zeros((2, 2)), resolution=1.0)))) == 2
