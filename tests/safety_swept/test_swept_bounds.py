"""The sampling bounds of the swept-footprint check (docs/safety.md, "Why it is conservative"):
the gain bound B holds for any gain between two samples, and the check keeps the margin in a
fine replay of its model however coarsely it is told to sample (the bounds are what make it
safe, not the default sampling's density)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.safety.swept import SweptConfig, SweptFootprint

from .test_swept_unit import A, B, R, _brute_force_touches, jackal, polar

pytestmark = pytest.mark.unit

CORNERS = np.array([[A, B], [A, -B], [-A, B], [-A, -B]])


def test_the_gain_bound_covers_every_footprint_corner_between_two_sampled_gains():
    """Per unit of yaw gain no footprint point moves farther than B (_gain_sensitivity); the
    corners are the farthest points, so checking them checks the footprint."""
    rng = np.random.default_rng(7)
    swept = SweptFootprint(jackal())
    for _ in range(40):
        command = np.array([rng.uniform(-0.8, 2.0), 0.0, rng.uniform(-3.0, 3.0)])
        previous = np.array([rng.uniform(-0.5, 2.0), 0.0, rng.uniform(-3.0, 3.0)])
        tw = swept.twists(command, previous, 0.02, np.array([1.0]))
        bound = float(swept._gain_sensitivity(tw)[0])
        g0, dg = 0.6, 0.05
        fine = np.linspace(g0, g0 + dg, 11)
        poses = swept.poses(tw, fine)[0]  # (11, K + 1, 3)
        c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
        corners = np.stack([poses[..., 0:1] + c[..., None] * CORNERS[:, 0] - s[..., None] * CORNERS[:, 1],
                            poses[..., 1:2] + s[..., None] * CORNERS[:, 0] + c[..., None] * CORNERS[:, 1]], axis=-1)
        # Each fine gain against the nearer end of the interval: within dg / 2 * B.
        nearest = np.where((fine - g0 <= dg / 2)[:, None, None], 0, -1)
        ends = np.where(nearest[..., None] == 0, corners[:1], corners[-1:])
        moved = np.max(np.linalg.norm(corners - ends, axis=-1))
        assert moved <= 0.5 * dg * bound + 1e-9, (command, previous, moved, bound)


@pytest.mark.parametrize("config", [SweptConfig(), SweptConfig(max_gains=2), SweptConfig(time_step=0.05, max_gains=3)],
                         ids=["default", "two-gains", "coarse-time"])
def test_whatever_it_lets_through_keeps_the_margin_however_coarsely_it_samples(config):
    rng = np.random.default_rng(380)
    swept = SweptFootprint(jackal(), config)
    checked = 0
    for _ in range(40):
        pts = polar(rng.uniform(R - 0.08, R + 0.6), rng.uniform(-math.pi, math.pi)) + rng.normal(0.0, 0.05, size=(6, 2))
        pts = pts[swept.clearance(np.zeros(3), pts) > config.margin]
        if not len(pts):
            continue
        command = np.array([rng.uniform(-0.8, 1.5), 0.0, rng.uniform(-2.5, 2.5)])
        previous = np.array([rng.uniform(-0.3, 1.0), 0.0, rng.uniform(-1.0, 1.0)])
        result = swept.check(command, previous, pts, lead=0.02)
        if result.blocked:
            continue
        assert not _brute_force_touches(swept, command, previous, pts, 0.02, result.scale, config.margin), (command, previous, result)
        checked += 1
    assert checked > 20


def test_a_touch_while_the_pipe_drives_blocks_even_a_stop():
    """The poses while the commands already sent drive the robot are every candidate's: a touch
    there within every candidate's limit is reported as blocked (a stop touches too)."""
    swept = SweptFootprint(jackal())
    radius = R - 0.02
    side = math.atan2(B, math.sqrt(radius * radius - B * B))  # where the circle leaves the left side
    # Already turning left at 2 rad/s: the latency alone swings the side 3 degrees on.
    turning = swept.check(np.zeros(3), np.array([0.0, 0.0, 2.0]), polar(radius, side + math.radians(3)))
    assert turning.blocked and turning.stopped
    # Turning right (away) at the same speed: the same point is free for a stop.
    assert not swept.check(np.zeros(3), np.array([0.0, 0.0, -2.0]), polar(radius, side + math.radians(3))).blocked
