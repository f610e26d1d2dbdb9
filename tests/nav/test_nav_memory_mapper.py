"""Mapping with scan matching (MemoryMapper): drifting odometry, corrected pose, obstacle memory."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.mapping import MemoryMapper
from tests.nav.components.fake_base import BOXES, ROOM, ray_boxes

pytestmark = pytest.mark.unit


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


def _reference_match(matcher, grid, guess, pts_local):
    """The matcher's search written out plainly: every candidate pose moves every hit, cells
    outside the window score 0. The fast version must choose exactly as this one does."""
    from emos.actors.nav.maps.edt import euclidean_distance_transform

    pts = pts_local[:: max(1, len(pts_local) // matcher.max_points)]
    field = np.exp(-0.5 * (euclidean_distance_transform(grid.occupied, grid.resolution) / matcher.sigma) ** 2).astype(np.float32)
    yaws = guess[2] + matcher.dyaw
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    rx, ry = c * pts[:, 0] - s * pts[:, 1] + guess[0], s * pts[:, 0] + c * pts[:, 1] + guess[1]
    gx = rx[:, None, None, :] + matcher.dxy[None, :, None, None]
    gy = ry[:, None, None, :] + matcher.dxy[None, None, :, None]
    cols = np.floor((gx - grid.origin[0]) / grid.resolution).astype(np.int64)
    rows = np.floor((gy - grid.origin[1]) / grid.resolution).astype(np.int64)
    inside = (rows >= 0) & (rows < grid.shape[0]) & (cols >= 0) & (cols < grid.shape[1])
    score = np.where(inside, field[np.clip(rows, 0, grid.shape[0] - 1), np.clip(cols, 0, grid.shape[1] - 1)], 0.0).mean(axis=-1)
    prior = 1.0 - 0.02 * (np.abs(matcher.dyaw)[:, None, None] / matcher.dyaw.max()
                          + (np.abs(matcher.dxy)[None, :, None] + np.abs(matcher.dxy)[None, None, :]) / matcher.dxy.max())
    best = np.unravel_index(int(np.argmax(score * prior)), score.shape)
    k0 = len(matcher.dyaw) // 2, len(matcher.dxy) // 2, len(matcher.dxy) // 2
    pose = np.array([guess[0] + matcher.dxy[best[1]], guess[1] + matcher.dxy[best[2]], yaws[best[0]]])
    return pose, float(score[best]), float(score[k0])


def test_scan_matching_chooses_exactly_as_the_plain_search_also_at_the_window_edge():
    from emos.actors.nav.mapping.hit_grid import HitGrid
    from emos.actors.nav.mapping.scan_matching import ScanMatcher

    rng = np.random.default_rng(7)
    grid = HitGrid((-5.0, -1.0, 1.0, 15.0), 0.05)
    grid.insert(rng.uniform([-5, -1], [1, 15], (3000, 2)))
    matcher = ScanMatcher()
    for k in range(40):
        if k % 8 == 0:
            grid.insert(rng.uniform([-5, -1], [1, 15], (40, 2)))  # the field is rebuilt when the memory grows
        # Guesses beyond the window too: hits that fall outside it must score 0 in both.
        guess = np.array([rng.uniform(-5.5, 1.5), rng.uniform(-1.5, 15.5), rng.uniform(-3.0, 3.0)])
        pts = rng.uniform(-6.0, 6.0, (int(rng.integers(20, 720)), 2))
        got, want = matcher.match(grid, guess, pts), _reference_match(matcher, grid, guess, pts)
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1:] == want[1:], k


def test_match_margin_is_checked_and_reaches_the_memory_from_the_local_mapper_config():
    import pytest

    from emos.actors.nav.components.local_mapper import LocalMapperConfig, memory_of

    with pytest.raises(ValueError, match="match_margin"):
        MemoryMapper((0, 0, 4, 4), match_margin=float("nan"))
    with pytest.raises(ValueError, match="match_margin"):
        LocalMapperConfig(mapping_bounds=(0, 0, 4, 4), match_margin=-0.1)
    assert memory_of(LocalMapperConfig()) is None  # no mapping window: no memory
    assert memory_of(LocalMapperConfig(mapping_bounds=(0, 0, 4, 4))).match_margin == 0.01
    assert memory_of(LocalMapperConfig(mapping_bounds=(0, 0, 4, 4), match_margin=0.0)).match_margin == 0.0
