"""The DriveManager's blind-spot memory: obstacles seen a moment ago still count where the laser
cannot see now, never where it can."""
import math

import numpy as np
import pytest

from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.safety.blind_spot import BlindSpotConfig, BlindSpotMemory

pytestmark = pytest.mark.unit

FOV = math.radians(270)


def scan_of_points(points: np.ndarray, fov: float = FOV, beams: int = 540) -> LaserScan2D:
    """A scan (sensor at the robot's centre) whose beams end at the nearest of ``points``."""
    angles = -0.5 * fov + np.arange(beams) * (fov / beams)
    ranges = np.full(beams, np.inf)
    if len(points):
        bearing = np.arctan2(points[:, 1], points[:, 0])
        for b, a in enumerate(angles):
            hit = np.abs((bearing - a + math.pi) % (2 * math.pi) - math.pi) < 0.5 * fov / beams
            if hit.any():
                ranges[b] = float(np.hypot(points[hit, 0], points[hit, 1]).min())
    return LaserScan2D(ranges=ranges, angle_min=-0.5 * fov, angle_increment=fov / beams, range_max=30.0)


WALL = np.c_[np.full(41, -1.0), np.linspace(-1.0, 1.0, 41)]  # odometry frame: x = -1


def test_a_wall_seen_ahead_is_remembered_once_it_is_behind():
    memory = BlindSpotMemory()
    facing_west = np.array([0.0, 0.0, math.pi])
    local_wall = np.c_[-WALL[:, 0], -WALL[:, 1]]  # robot frame when facing west: the wall 1 m ahead
    memory.update(facing_west, scan_of_points(local_wall), now=0.0)
    assert len(memory) > 20
    facing_east = np.array([0.0, 0.0, 0.0])
    now_scan = scan_of_points(np.zeros((0, 2)))  # nothing in the 270 degree view
    behind = memory.blind_points(facing_east, now_scan)
    assert len(behind) > 5
    assert np.all(behind[:, 0] < -0.9) and np.all(np.abs(np.arctan2(behind[:, 1], -behind[:, 0])) <= math.radians(45) + 0.02)


def test_memory_is_not_used_where_the_laser_looks_and_forgets_old_and_far_points():
    memory = BlindSpotMemory(BlindSpotConfig(memory_time=5.0, radius=2.0))
    pose = np.array([0.0, 0.0, 0.0])
    ahead = np.array([[1.0, 0.0]])
    memory.update(pose, scan_of_points(ahead), now=0.0)
    # The obstacle ahead left: the current scan (which looks there) is the truth.
    assert len(memory.blind_points(pose, scan_of_points(np.zeros((0, 2))))) == 0
    # A full-turn laser has no blind sector at all.
    memory.update(np.array([0.0, 0.0, math.pi]), scan_of_points(ahead), now=1.0)
    assert len(memory.blind_points(pose, scan_of_points(np.zeros((0, 2)), fov=2 * math.pi, beams=720))) == 0
    assert len(memory.blind_points(pose, scan_of_points(np.zeros((0, 2))))) == 1  # the one at (-1, 0), behind
    memory.update(pose, scan_of_points(np.zeros((0, 2))), now=7.0)  # older than memory_time
    assert len(memory) == 0
    memory.update(pose, scan_of_points(np.array([[-0.5, 0.0]]) * -1), now=8.0)
    memory.update(np.array([5.0, 0.0, 0.0]), scan_of_points(np.zeros((0, 2))), now=8.1)  # drove 5 m away
    assert len(memory) == 0


def test_one_point_per_cell_keeps_the_memory_small():
    memory = BlindSpotMemory(BlindSpotConfig(resolution=0.1))
    dense = np.c_[np.full(500, 1.0), np.linspace(-0.5, 0.5, 500)]
    for t in range(20):
        memory.update(np.array([0.0, 0.0, 0.0]), scan_of_points(dense, beams=1080), now=0.1 * t)
    assert len(memory) <= 12


def test_bad_settings_are_refused_with_the_name():
    with pytest.raises(ValueError, match="memory_time"):
        BlindSpotConfig(memory_time=-1.0)
