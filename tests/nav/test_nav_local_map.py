import math

import numpy as np
import pytest

from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.local_map import FREE, OCCUPIED, UNKNOWN, LocalMapper, MapConfig, MapperConfig

pytestmark = pytest.mark.unit


def full_scan(ranges, range_max=10.0):
    ranges = np.asarray(ranges, dtype=float)
    return LaserScan2D(ranges, angle_min=-math.pi, angle_increment=2 * math.pi / ranges.size, range_max=range_max)


@pytest.mark.parametrize("tracer", ["update", "trace_rays"])
def test_wall_in_front_free_before_occupied_at_unknown_behind(tracer):
    n = 720
    ang = -math.pi + np.arange(n) * 2 * math.pi / n
    # a wall x = 1.0 in front (|angle| < 45 deg), nothing elsewhere (inf = no return)
    ranges = np.where(np.abs(ang) < math.pi / 4, 1.0 / np.cos(ang), np.inf)
    mapper = LocalMapper(MapConfig(width=4.0, height=4.0, resolution=0.05))
    grid = getattr(mapper, tracer)(full_scan(ranges, range_max=1.5))
    assert grid.shape == (80, 80)
    assert grid[mapper.cell_of(1.02, 0.0)] == OCCUPIED
    assert grid[mapper.cell_of(1.02, 0.5)] == OCCUPIED
    assert all(grid[mapper.cell_of(x, 0.0)] == FREE for x in np.arange(0.1, 0.95, 0.05))
    assert grid[mapper.cell_of(1.5, 0.0)] == UNKNOWN  # behind the wall
    # no return behind the robot: free up to range_max, unknown beyond
    assert grid[mapper.cell_of(-1.3, 0.0)] == FREE
    assert grid[mapper.cell_of(-1.8, 0.0)] == UNKNOWN


def test_nan_beams_carry_no_information():
    n = 360
    ranges = np.full(n, 2.02)
    ranges[170:190] = np.nan  # around angle 0
    mapper = LocalMapper(MapConfig(width=6.0, height=6.0, resolution=0.05))
    grid = mapper.update(full_scan(ranges))
    assert grid[mapper.cell_of(1.0, 0.0)] == UNKNOWN
    assert grid[mapper.cell_of(-1.0, 0.0)] == FREE
    assert grid[mapper.cell_of(-2.03, 0.0)] == OCCUPIED


def test_fast_path_agrees_with_ray_sampling():
    th = np.linspace(-math.pi, math.pi, 3600, endpoint=False)
    scan = full_scan(2.0 + 0.8 * np.sin(7 * th), range_max=5.0)
    mapper = LocalMapper(MapConfig(width=8.0, height=8.0, resolution=0.05))
    fast = mapper.update(scan).copy()
    slow = mapper.trace_rays(scan).copy()
    assert np.array_equal(fast == OCCUPIED, slow == OCCUPIED)
    assert np.mean(fast == slow) > 0.99


def test_sparse_scan_leaves_gaps_between_beams_unknown():
    mapper = LocalMapper(MapConfig(width=10.0, height=10.0, resolution=0.05))
    grid = mapper.update(full_scan(np.full(8, np.inf), range_max=4.5))  # 8 beams, 45 deg apart
    assert grid[mapper.cell_of(4.0, 0.0)] == FREE  # on a beam
    assert grid[mapper.cell_of(4.0 * math.cos(0.39), 4.0 * math.sin(0.39))] == UNKNOWN  # between


def test_sensor_offset_shifts_the_rays():
    ranges = np.full(360, 1.0)
    mapper = LocalMapper(MapConfig(width=4.0, height=4.0, resolution=0.05), sensor_pose=(0.5, 0.0, 0.0))
    grid = mapper.update(full_scan(ranges))
    assert grid[mapper.cell_of(1.52, 0.0)] == OCCUPIED
    assert grid[mapper.cell_of(-0.48, 0.0)] == OCCUPIED


def test_config_validation_and_alias():
    assert MapperConfig is MapConfig
    assert MapConfig(width=5.0, height=3.0, resolution=0.2).shape == (15, 25)
    with pytest.raises(ValueError, match="resolution"):
        MapConfig(resolution=0.0)
    with pytest.raises(ValueError, match="coarser"):
        MapConfig(width=1000.0, height=1.0, resolution=0.01)


def _front_cone_scan(obstacle_x=None):
    """A 90 degree field of view; optionally a wall x = obstacle_x ahead."""
    ang = np.linspace(-math.pi / 4, math.pi / 4, 181)
    ranges = np.full(ang.size, np.inf) if obstacle_x is None else obstacle_x / np.cos(ang)
    return LaserScan2D(ranges, angles=ang, range_max=3.0)


def test_memory_rolls_obstacles_along_with_the_robot():
    cfg = MapConfig(width=6.0, height=6.0, resolution=0.05)
    plain = LocalMapper(cfg)
    rolling = LocalMapper(cfg, keep_memory=True)
    start = np.array([0.0, 0.0, 0.0])
    for m in (plain, rolling):
        m.update(_front_cone_scan(1.0), start)
    # turn around and move 0.5 m: the wall is now 1.5 m behind, outside the field of view
    turned = np.array([-0.5, 0.0, math.pi])
    g_plain = plain.update(_front_cone_scan(None), turned)
    g_roll = rolling.update(_front_cone_scan(None), turned)
    behind = rolling.cell_of(-1.52, 0.0)  # world x = 1.02 seen from the new pose
    assert g_plain[behind] == UNKNOWN
    assert g_roll[behind] == OCCUPIED
    assert g_roll[rolling.cell_of(1.0, 0.0)] == FREE  # what the new scan sees wins


def test_memory_clears_a_stale_obstacle_when_a_beam_passes_through():
    rolling = LocalMapper(MapConfig(width=6.0, height=6.0, resolution=0.05), keep_memory=True)
    rolling.update(_front_cone_scan(1.0), np.zeros(3))
    grid = rolling.update(_front_cone_scan(None), np.zeros(3))  # the obstacle walked away
    assert grid[rolling.cell_of(1.02, 0.0)] == FREE
