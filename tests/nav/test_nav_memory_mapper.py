"""Mapping with scan matching (MemoryMapper): drifting odometry, corrected pose, obstacle memory."""
from __future__ import annotations

import math

import numpy as np

from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.mapping import MemoryMapper
from tests.nav.components.fake_base import BOXES, ROOM, ray_boxes


def _scan(pose) -> LaserScan2D:
    angles = -math.pi + np.arange(360) * (2 * math.pi / 360)
    r = ray_boxes(pose[0], pose[1], angles + pose[2], [ROOM] + BOXES)
    return LaserScan2D(ranges=r, angle_min=-math.pi, angle_increment=2 * math.pi / 360, range_max=10.0)


def test_scan_matching_keeps_the_pose_while_odometry_drifts():
    mapper = MemoryMapper((-0.5, -0.5, 6.5, 4.5), 0.05)
    odom_only = MemoryMapper((-0.5, -0.5, 6.5, 4.5), 0.05, scan_matching=False)
    errors, odom_errors = [], []
    for k in range(80):
        true = np.array([1.0 + 0.02 * k, 3.2, 0.0])
        odom = true + np.array([0.004 * k, -0.003 * k, 0.002 * k])  # 32 cm, 24 cm and 9 deg of drift at the end
        scan = _scan(true)
        est = mapper.update(scan, odom)
        odom_only.update(scan, odom)
        errors.append(math.hypot(*(est[:2] - true[:2])))
        odom_errors.append(math.hypot(*(odom[:2] - true[:2])))
    assert odom_errors[-1] > 0.35
    assert max(errors) < 0.08
    # The memory holds the walls where they are: a wall point is occupied, the room centre free.
    occ = mapper.occupancy()
    def cell(x, y):
        return occ[int((y + 0.5) / 0.05), int((x + 0.5) / 0.05)]
    assert any(cell(3.0, 2.6 + d) == 100 for d in (-0.05, 0.0, 0.05))  # the top of the wall from the bottom
    assert any(cell(6.0 + d, 2.0) == 100 for d in (-0.05, 0.0, 0.05))  # the room's right wall
    assert cell(1.5, 3.2) == 0
    # Without matching the same scans smear: more occupied cells for the same walls.
    assert (odom_only.occupancy() == 100).sum() > 1.3 * (occ == 100).sum()


def test_memory_mapper_rejects_non_finite_odometry():
    import pytest

    mapper = MemoryMapper((0, 0, 4, 4))
    with pytest.raises(ValueError, match="odom_pose"):
        mapper.update(_scan((1.0, 1.0, 0.0)), np.array([np.nan, 0.0, 0.0]))
