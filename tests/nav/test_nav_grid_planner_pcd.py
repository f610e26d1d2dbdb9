"""The cost-to-go grid planner and point-cloud maps (pure algorithms, no processes)."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.maps import MapFileError, OccupancyGridMap
from emos.actors.nav.maps.pcd import cloud_to_grid, read_pcd
from emos.actors.nav.planning.grid_planner import CostToGoPlanner
from emos.actors.nav.robot import RobotConfig

pytestmark = pytest.mark.unit


def _room() -> OccupancyGridMap:
    data = np.zeros((80, 120), dtype=np.int8)
    data[:2], data[-2:], data[:, :2], data[:, -2:] = 100, 100, 100, 100
    data[:52, 56:64] = 100  # a wall from the bottom, open at the top
    return OccupancyGridMap(data=data, resolution=0.05, origin=(0.0, 0.0, 0.0))


def _robot() -> RobotConfig:
    return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="CYLINDER", geometry_params=np.array([0.15, 0.3]))


def test_cost_to_go_goes_round_the_wall_with_clearance():
    grid = _room()
    planner = CostToGoPlanner(_robot())
    planner.set_map(grid)
    result = planner.plan((1.0, 1.0, 0.0), (4.5, 1.0))
    assert result.solved, result.message
    path = result.path
    assert np.allclose(path[0, :2], (1.0, 1.0)) and np.allclose(path[-1, :2], (4.5, 1.0), atol=1e-6)
    assert path[:, 1].max() > 2.6  # over the top of the wall
    occ = np.argwhere(grid.data >= 65)[:, ::-1]
    centres = grid.grid_to_world(occ)
    d = np.min(np.hypot(path[:, None, 0] - centres[None, :, 0], path[:, None, 1] - centres[None, :, 1]), axis=1)
    assert d.min() > 0.15  # the robot's radius


def test_cost_to_go_rejects_goals_in_obstacles_off_the_map_and_unreachable():
    planner = CostToGoPlanner(_robot())
    grid = _room()
    planner.set_map(grid)
    bad = planner.plan((1.0, 1.0, 0.0), (3.0, 1.0))
    assert not bad.solved and bad.status == "INVALID_GOAL"
    with pytest.raises(ValueError, match="outside the map"):
        planner.plan((1.0, 1.0, 0.0), (40.0, 1.0))
    closed = grid.data.copy()
    closed[:, 56:64] = 100
    planner.set_map(grid.copy_with(closed))
    none = planner.plan((1.0, 1.0, 0.0), (4.5, 1.0))
    assert not none.solved and none.status == "NO_SOLUTION"


def test_pcd_ascii_and_binary_project_a_height_slice(tmp_path):
    pts = np.array([[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [1.0, 1.0, 0.01], [0.5, 0.5, 3.0], [np.nan, 0, 0]], dtype=np.float32)
    head = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 5\nHEIGHT 1\nPOINTS 5\nDATA {}\n"
    (tmp_path / "a.pcd").write_text(head.format("ascii") + "\n".join(" ".join(str(v) for v in p) for p in pts))
    (tmp_path / "b.pcd").write_bytes(head.format("binary").encode() + pts.tobytes())
    for name in ("a.pcd", "b.pcd"):
        cloud = read_pcd(tmp_path / name)
        assert cloud.shape == (4, 3)
        grid = cloud_to_grid(cloud, 0.1, 0.05, 2.0, padding=0.2)
        assert int((grid.data == 100).sum()) == 2  # the ground point and the high point are not obstacles
        assert grid.values_at(np.array([[1.0, 0.0]]))[0] == 100
    (tmp_path / "c.pcd").write_text("VERSION .7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nPOINTS 0\nDATA ascii\n")
    with pytest.raises(MapFileError, match=r"c\.pcd.*no field"):
        read_pcd(tmp_path / "c.pcd")
    with pytest.raises(MapFileError, match="missing.pcd"):
        read_pcd(tmp_path / "missing.pcd")

