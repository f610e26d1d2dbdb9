"""The pieces of the stuck recovery, without processes: the progress checker, the shared
clearance band, and the CostToGo planner's escape from the lethal band and its blocks."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.maps import OccupancyGridMap
from emos.actors.nav.planning.costfield import CLEARANCE_BAND
from emos.actors.nav.planning.grid_planner import CostToGoPlanner
from emos.actors.nav.robot import RobotConfig
from emos.actors.nav.stuck import ProgressChecker

pytestmark = pytest.mark.unit


def _jackal() -> RobotConfig:
    return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([0.508, 0.43, 0.25]))


def test_progress_checker_reports_a_stall_once_per_timeout_and_forgives_progress():
    check = ProgressChecker(timeout=3.0, distance=0.3)
    assert not check.update(0.0, 10.0)
    assert not check.update(2.9, 9.8)  # 0.2 m: not enough, but not 3 s yet
    assert check.update(3.0, 9.8)  # stall
    assert not check.update(4.0, 9.8)  # counting again from the stall
    assert not check.update(5.0, 9.4)  # progress resets the clock
    assert not check.update(7.9, 9.4) and check.update(8.0, 9.4)
    with pytest.raises(ValueError, match="timeout and distance"):
        ProgressChecker(0.0, 0.3)


def _corridor_with_gap(gap_m: float) -> OccupancyGridMap:
    """A 4 m x 3 m room split by a wall at x = 2 with one gap of ``gap_m`` at y = 1.5."""
    res = 0.05
    data = np.zeros((60, 80), dtype=np.int8)
    data[:1], data[-1:], data[:, :1], data[:, -1:] = 100, 100, 100, 100
    data[:, 40] = 100
    half = int(round(gap_m / res / 2))
    data[30 - half: 30 + half, 40] = 0
    return OccupancyGridMap(data=data, resolution=res, origin=(0.0, 0.0, 0.0))


def test_cost_to_go_plans_through_a_gap_the_box_fits_and_not_one_it_does_not():
    planner = CostToGoPlanner(_jackal())
    planner.set_map(_corridor_with_gap(0.6))  # wider than the 0.43 m robot, narrower than its 0.66 m diagonal
    ok = planner.plan((1.0, 1.5, 0.0), (3.0, 1.5))
    assert ok.solved, ok.message  # the circumscribed radius used to close this gap
    assert planner._field.lethal_radius == pytest.approx(0.215 - 0.025)
    assert planner._field.soft_radius == pytest.approx(0.215 + CLEARANCE_BAND)
    planner.set_map(_corridor_with_gap(0.3))
    assert planner.plan((1.0, 1.5, 0.0), (3.0, 1.5)).status == "NO_SOLUTION"


def test_cost_to_go_plans_a_robot_out_of_the_lethal_band_and_routes_round_blocks():
    planner = CostToGoPlanner(_jackal())
    grid = _corridor_with_gap(0.6)
    planner.set_map(grid)
    near_wall = (1.85, 1.0, 0.0)  # 0.12 m from the wall: inside the lethal band
    result = planner.plan(near_wall, (3.0, 1.5))
    assert result.solved, result.message
    assert np.allclose(result.path[0, :2], near_wall[:2])
    assert result.path[:, 0].max() > 2.5
    # Block the gap (the only way across): nothing remains, so the block is forgotten.
    planner.plan((1.0, 1.5, 0.0), (3.0, 1.5))
    spot = planner.block_tightest_spot((1.0, 1.5), ahead=3.0)
    assert spot is not None and abs(spot[0] - 2.0) < 0.1 and abs(spot[1] - 1.5) < 0.1
    again = planner.plan((1.0, 1.5, 0.0), (3.0, 1.5))
    assert again.solved and planner.blocks == []
    # A second gap, lower down: the block sends the plan through it.
    data = grid.data.copy()
    data[4:16, 40] = 0
    planner.set_map(grid.copy_with(data))
    first = planner.plan((1.0, 1.5, 0.0), (3.0, 1.5))
    planner.block_tightest_spot((1.0, 1.5), ahead=3.0)
    second = planner.plan((1.0, 1.5, 0.0), (3.0, 1.5))
    assert second.solved and planner.blocks
    crossing = lambda path: path[np.argmin(abs(path[:, 0] - 2.0)), 1]  # noqa: E731
    assert abs(crossing(first.path) - 1.5) < 0.1
    assert crossing(second.path) < 0.9  # through the lower gap
