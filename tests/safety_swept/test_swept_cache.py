"""The swept check's per-scan cache and its faster arithmetic: the prepared points answer as
the raw ones do, are built once per scan, and the fast routines (the poses' arcs, the base's
response, the least distance without a square root per pose) agree with their references
(emos.geometry.integrate_pose, the brute-force running maximum, clearance())."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.safety import DriveSafety, SafetyZonesConfig, ScanCache, SweptConfig, SweptPoints
from emos.actors.nav.safety.swept import SweptFootprint, _window_max
from emos.geometry import integrate_pose

from .test_swept_unit import jackal

pytestmark = pytest.mark.unit


def _posts(rng: np.random.Generator, count: int = 40) -> np.ndarray:
    """Scan-like points on posts (radius 0.075 m) around the robot, none inside it."""
    centres = rng.uniform(-2.5, 2.5, (count, 2))
    centres = centres[np.hypot(centres[:, 0], centres[:, 1]) > 0.5]
    ang = np.linspace(0.0, 2 * math.pi, 12, endpoint=False)
    return (centres[:, None, :] + 0.075 * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)


def test_prepared_points_give_the_same_answer_as_raw_points():
    rng = np.random.default_rng(5)
    swept = SweptFootprint(jackal())
    points = _posts(rng)
    prepared = swept.prepare(points)
    assert isinstance(prepared, SweptPoints) and len(prepared) == len(points)
    assert np.all(np.diff(prepared.norm2) >= 0.0)  # sorted by distance from the centre
    outcomes = set()
    for _ in range(150):
        cmd = np.array([rng.uniform(-0.5, 2.0), 0.0, rng.uniform(-3.0, 3.0)])
        prev = np.clip(cmd + np.array([rng.normal(0, 0.2), 0.0, rng.normal(0, 0.3)]), -3, 3)
        raw = swept.check(cmd, prev, points, lead=0.02)
        # The points in another order, prepared once, reused for every command.
        again = swept.check(cmd, prev, prepared, lead=0.02)
        assert (raw.scale, raw.blocked) == (again.scale, again.blocked)
        assert raw.clearance == pytest.approx(again.clearance, abs=1e-9) or raw.clearance == again.clearance
        outcomes.add((raw.scale, raw.blocked))
    assert len(outcomes) >= 3  # let through, slowed and stopped all happened


def test_points_prepared_for_another_footprint_are_prepared_again():
    points = _posts(np.random.default_rng(1))
    small, big = SweptFootprint(jackal()), SweptFootprint(jackal(), SweptConfig(margin=0.3))
    prepared = small.prepare(points)
    assert small.prepare(prepared) is prepared
    other = big.prepare(prepared)
    assert other is not prepared and other.footprint is big


def test_scan_cache_builds_once_per_scan_message():
    cache, built = ScanCache(), []

    def build() -> SweptPoints:
        built.append(1)
        return SweptFootprint(jackal()).prepare(np.zeros((0, 2)))

    first, second = object(), object()
    a = cache.get(first, True, build)
    assert cache.get(first, True, build) is a and len(built) == 1
    cache.get(first, False, build)  # something else it depends on changed (the pose became known)
    assert len(built) == 2
    cache.get(second, False, build)  # a new scan
    assert len(built) == 3
    cache.get(None, False, build)
    cache.get(None, False, build)  # no message to tell scans apart: never reused
    assert len(built) == 5


def test_drive_safety_prepares_a_scans_points_once():
    safety = DriveSafety(jackal(), SafetyZonesConfig(), swept=SweptConfig())
    points = _posts(np.random.default_rng(2))
    calls = []

    def build() -> np.ndarray:
        calls.append(1)
        return points

    scan = object()
    for _ in range(5):
        prepared = safety.swept_points(scan, True, build)
        safety.limit_swept(np.array([1.0, 0.0, 0.5]), np.array([1.0, 0.0, 0.5]), prepared, 0.02)
    assert len(calls) == 1
    assert DriveSafety(jackal(), SafetyZonesConfig()).swept_points(scan, True, build) is None  # check off


def test_poses_are_the_exact_arcs_of_integrate_pose():
    rng = np.random.default_rng(3)
    swept = SweptFootprint(jackal())
    dt = swept.config.time_step
    twists = rng.normal(size=(3, 30, 3)) * np.array([1.0, 0.3, 2.0])
    twists[rng.random((3, 30)) < 0.3, 2] = 0.0  # straight steps too
    gains = np.array([0.6, 0.9, 1.2])
    poses = swept.poses(twists, gains)
    for c in range(3):
        for g, gain in enumerate(gains):
            pose = np.zeros(3)
            for k in range(30):
                tw = twists[c, k] * np.array([1.0, 1.0, gain])
                pose = integrate_pose(pose, tw, dt)
                assert poses[c, g, k + 1, :2] == pytest.approx(pose[:2], abs=1e-9)
                assert math.remainder(poses[c, g, k + 1, 2] - pose[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_the_running_maximum_matches_brute_force():
    rng = np.random.default_rng(4)
    values = rng.random((3, 50))
    for width in range(1, 30):
        expect = np.array([[row[max(0, k - width + 1):k + 1].max() for k in range(50)] for row in values])
        assert np.array_equal(_window_max(values, width), expect)


def test_least_distance_matches_clearance_inside_and_out():
    rng = np.random.default_rng(6)
    swept = SweptFootprint(jackal())
    poses = rng.normal(scale=[0.4, 0.4, 2.0], size=(2, 3, 7, 3))
    points = rng.uniform(-0.8, 0.8, (25, 2))  # some inside the footprint at some poses
    prepared = swept.prepare(points)
    c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
    x, y = poses[..., 0], poses[..., 1]
    frames = np.stack([np.stack([c, s, -(c * x + s * y)], -1), np.stack([-s, c, s * x - c * y], -1)], -2)
    least, head = swept._least_distance(frames, prepared.homog, head=3)
    reference = swept.clearance(poses, prepared.points)  # (2, 3, 7, 25)
    assert (reference < 0).any()
    np.testing.assert_allclose(least, reference.min(axis=(1, 2)), atol=1e-12)
    np.testing.assert_allclose(head, reference[:, :, :3].min(axis=(1, 2)), atol=1e-12)
