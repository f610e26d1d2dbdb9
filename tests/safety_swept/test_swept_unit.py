"""The swept-footprint check alone: corner sweeps by pure rotation and by arcs, forward and
reverse, against obstacle points just inside and just outside what the footprint sweeps; and
its conservativeness against a brute-force replay of the same motion model."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig
from emos.actors.nav.safety.swept import SweptConfig, SweptFootprint

pytestmark = pytest.mark.unit

# The realistic Jackal as the BARN stack describes it (tools/barn/harness.py nav_robot).
LENGTH, WIDTH = 0.458, 0.4156
A, B = LENGTH / 2, WIDTH / 2
R = math.hypot(A, B)
CORNER = math.atan2(B, A)  # bearing of the front-left corner


def jackal() -> RobotConfig:
    return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([LENGTH, WIDTH, 0.282]),
                       ctrl_vx_limits=LinearCtrlLimits(max_vel=2.0, max_acc=20.0, max_decel=20.0),
                       ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=25.0, max_decel=25.0))


def polar(radius: float, bearing: float) -> np.ndarray:
    return np.array([[radius * math.cos(bearing), radius * math.sin(bearing)]])


STILL = np.zeros(3)


def _side_crossing(radius: float) -> float:
    """Bearing at which the circle of ``radius`` (< R) leaves the box through its left side."""
    return math.atan2(B, math.sqrt(radius * radius - B * B))


def test_a_rotation_that_swings_the_corner_into_a_point_is_refused_and_the_other_way_is_free():
    swept = SweptFootprint(jackal())
    # Just inside the corner's circle and just beside the left side (outside the footprint):
    # a left turn of 2 degrees swings the side into it, however slowly.
    radius = R - 0.02
    point = polar(radius, _side_crossing(radius) + math.radians(2))
    assert jackal().footprint_distance(point)[0] > 0.0
    assert swept.check(np.array([0.0, 0.0, 1.0]), STILL, point).scale == 0.0  # left: refused
    assert swept.check(np.array([0.0, 0.0, 0.3]), STILL, point).scale == 0.0  # slower: still touches
    assert swept.check(np.array([0.0, 0.0, -1.0]), STILL, point).scale == 1.0  # right: away from it, free
    # The mirror image on the right side: the right turn is refused.
    mirror = point * np.array([1.0, -1.0])
    assert swept.check(np.array([0.0, 0.0, -1.0]), STILL, mirror).scale == 0.0
    assert swept.check(np.array([0.0, 0.0, 1.0]), STILL, mirror).scale == 1.0


def test_a_point_just_outside_the_corner_circle_never_blocks_a_rotation():
    swept = SweptFootprint(jackal())
    for bearing in np.linspace(-math.pi, math.pi, 24, endpoint=False):
        point = polar(R + 0.035, bearing)  # beyond the circle the corners sweep, by more than the margin
        for w in (-2.0, -0.5, 0.5, 2.0):
            assert swept.check(np.array([0.0, 0.0, w]), STILL, point).scale == 1.0, (bearing, w)


def test_a_fast_rotation_is_slowed_when_its_stop_would_reach_a_point_that_a_slow_one_does_not():
    swept = SweptFootprint(jackal())
    # A point 25 degrees past where the left side meets its circle: a fast turn (its latency,
    # hold and yaw-lag tail) sweeps that far before it can stop, a slow one stops short of it.
    radius = R - 0.02
    point = polar(radius, _side_crossing(radius) + math.radians(25))
    fast = swept.check(np.array([0.0, 0.0, 2.0]), STILL, point)
    assert 0.0 < fast.scale < 1.0
    assert swept.check(np.array([0.0, 0.0, 2.0 * fast.scale]), STILL, point).scale == 1.0
    # Turning right moves the left side away from it (a fast right turn would sweep round to
    # the rear-left corner, which the circle meets again 90 degrees on).
    assert swept.check(np.array([0.0, 0.0, -1.0]), STILL, point).scale == 1.0


@pytest.mark.parametrize("v", [0.3, 0.8])
def test_a_forward_left_arc_into_a_point_beside_the_front_corner_is_stopped_or_slowed(v):
    swept = SweptFootprint(jackal())
    # 2 cm ahead of the front-left corner and 6 cm left of it: beside the straight path and
    # outside the circle the corners sweep, inside the sweep of a left arc.
    point = np.array([[A + 0.02, B + 0.06]])
    arc = swept.check(np.array([v, 0.0, 1.5]), STILL, point)
    assert arc.scale < 1.0
    assert swept.check(np.array([v, 0.0, 0.0]), STILL, point).scale == 1.0  # straight on passes it
    assert swept.check(np.array([0.0, 0.0, 1.5]), STILL, point).scale == 1.0  # so does a rotation
    # A right arc leaves it behind on the left: free.
    assert swept.check(np.array([v, 0.0, -1.5]), STILL, point).scale == 1.0


def test_reversing_arcs_check_the_rear_corners():
    swept = SweptFootprint(jackal())
    point = np.array([[-A - 0.04, -B - 0.02]])  # behind the rear-right corner
    # Backing up while turning left (v < 0, w > 0) swings the tail to the right, into it.
    assert swept.check(np.array([-0.4, 0.0, 1.0]), STILL, point).scale < 1.0
    assert swept.check(np.array([-0.4, 0.0, 0.0]), STILL, point).scale < 1.0  # straight back: it is in the path too
    # Driving forward (either way) leaves it behind.
    assert swept.check(np.array([0.4, 0.0, 1.0]), STILL, point).scale == 1.0
    assert swept.check(np.array([0.4, 0.0, -1.0]), STILL, point).scale == 1.0


def test_a_robot_already_too_close_may_move_away_but_not_nearer():
    swept = SweptFootprint(jackal())
    point = np.array([[A + 0.005, 0.0]])  # 5 mm ahead, inside the margin
    assert swept.check(np.array([-0.3, 0.0, 0.0]), STILL, point).scale == 1.0
    assert swept.check(np.array([0.3, 0.0, 0.0]), STILL, point).scale == 0.0


def test_what_the_robot_does_during_the_latency_counts_and_a_stop_that_touches_is_reported():
    swept = SweptFootprint(jackal(), SweptConfig(latency=0.2))
    point = np.array([[A + 0.1, 0.0]])  # 10 cm ahead
    moving = np.array([1.0, 0.0, 0.0])  # at 1 m/s the latency alone covers 0.2 m
    result = swept.check(np.zeros(3), moving, point)
    assert result.scale == 0.0 and result.blocked
    assert swept.check(np.zeros(3), np.array([0.2, 0.0, 0.0]), point).blocked is False  # 4 cm + braking: short of it


def test_far_points_cost_nothing_and_standing_still_is_always_free():
    swept = SweptFootprint(jackal())
    far = polar(5.0, 0.0)
    assert swept.check(np.array([1.0, 0.0, 0.0]), STILL, far).scale == 1.0
    assert swept.check(STILL, STILL, np.array([[A + 0.001, 0.0]])).scale == 1.0
    assert swept.check(np.array([1.0, 0.0, 0.0]), STILL, np.zeros((0, 2))).scale == 1.0


def _brute_force_touches(swept: SweptFootprint, command, previous, points, lead, scale, margin) -> bool:
    """Replay the check's motion model at 1 ms (Euler steps, so not the check's own integration)
    and 41 yaw gains; does any point come within ``margin`` of the footprint (points already
    within it: come nearer)?"""
    cfg = swept.config
    tw = swept.twists(np.asarray(command, float), np.asarray(previous, float), lead, np.array([scale]))[0]  # (K, 3)
    sub = 20  # each of the check's steps split into 20 (the same piecewise-constant twists)
    dt = cfg.time_step / sub
    tw = np.repeat(tw, sub, axis=0)
    hi = swept.gain_values(tw[None])[-1]
    gains = np.linspace(cfg.yaw_gain_min, hi, 41)[:, None]
    heading = np.concatenate([np.zeros((41, 1)), np.cumsum(tw[None, :, 2] * gains * dt, axis=1)], axis=1)
    mid = 0.5 * (heading[:, 1:] + heading[:, :-1])
    x = np.concatenate([np.zeros((41, 1)), np.cumsum(tw[None, :, 0] * np.cos(mid) * dt, axis=1)], axis=1)
    y = np.concatenate([np.zeros((41, 1)), np.cumsum(tw[None, :, 0] * np.sin(mid) * dt, axis=1)], axis=1)
    poses = np.stack([x, y, heading], axis=-1).reshape(-1, 3)
    start = swept.clearance(np.zeros(3), points)
    d = swept.clearance(poses, points)
    return bool(np.any((d < margin) & (d < start - 1e-3)))


def test_whatever_it_lets_through_keeps_the_margin_in_a_fine_replay_of_its_model():
    """The inflation argument of docs/safety.md, checked numerically: the command the check
    lets through (scaled), replayed at 1 ms over 41 yaw gains, keeps every point beyond the
    margin (or no nearer than it started). Sampling errors are what this catches; the motion
    model itself is checked against the simulator in test_swept_sim.py."""
    rng = np.random.default_rng(38)
    swept = SweptFootprint(jackal())
    margin = swept.config.margin
    checked = 0
    for _ in range(60):
        bearing = rng.uniform(-math.pi, math.pi)
        radius = rng.uniform(R - 0.08, R + 0.6)
        pts = polar(radius, bearing) + rng.normal(0.0, 0.05, size=(6, 2))
        pts = pts[swept.clearance(np.zeros(3), pts) > margin]  # the robot starts clear of them
        if not len(pts):
            continue
        command = np.array([rng.uniform(-0.8, 1.5), 0.0, rng.uniform(-2.5, 2.5)])
        previous = np.array([rng.uniform(-0.3, 1.0), 0.0, rng.uniform(-1.0, 1.0)])
        result = swept.check(command, previous, pts, lead=0.02)
        if result.blocked:
            continue  # even a stop touches: nothing to vouch for
        assert not _brute_force_touches(swept, command, previous, pts, 0.02, result.scale, margin), (command, previous, pts, result)
        checked += 1
    assert checked > 30


def test_bad_settings_are_refused_with_their_name():
    with pytest.raises(ValueError, match="scales"):
        SweptConfig(scales=(0.5, 1.0))
    with pytest.raises(ValueError, match="yaw_gain_min"):
        SweptConfig(yaw_gain_min=0.0)
