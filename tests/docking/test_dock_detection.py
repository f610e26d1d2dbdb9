"""Dock detection and the approach law (actors/nav/docking.py), on synthetic scans."""
import math

import numpy as np
import pytest

from emos.actors.nav.docking import DockApproach, DockSpec, compose, detect_dock, dock_template, invert

pytestmark = pytest.mark.unit


def _v_points(dock_in_robot, spec, n=40, noise=0.003, seed=0):
    rng = np.random.default_rng(seed)
    pts = []
    for seg in dock_template(spec):
        t = np.linspace(0.05, 0.95, n)[:, None]
        local = seg[0] + t * (seg[1] - seg[0])
        c, s = math.cos(dock_in_robot[2]), math.sin(dock_in_robot[2])
        pts.append(np.c_[dock_in_robot[0] + c * local[:, 0] - s * local[:, 1], dock_in_robot[1] + s * local[:, 0] + c * local[:, 1]])
    return np.vstack(pts) + rng.normal(0, noise, (2 * n, 2))


def test_detects_the_dock_from_a_rough_estimate():
    spec = DockSpec()
    truth = np.array([1.0, 0.1, math.pi - 0.15])
    det = detect_dock(_v_points(truth, spec), truth + np.array([0.08, -0.07, 0.08]), spec)
    assert det.found, det.reason
    assert math.dist(det.pose[:2], truth[:2]) < 0.01 and abs(det.pose[2] - truth[2]) < math.radians(1.5)


def test_dock_not_found_says_why():
    spec = DockSpec()
    det = detect_dock(np.array([[3.0, 3.0], [3.1, 3.0]]), (1.0, 0.0, math.pi), spec)
    assert not det.found and "scan points within" in det.reason
    # A flat wall where the dock should be: one line, not a V.
    wall = np.c_[np.full(80, 1.0), np.linspace(-0.4, 0.4, 80)]
    det = detect_dock(wall, (1.0, 0.0, math.pi), spec)
    assert not det.found and det.reason


def test_approach_converges_on_the_docked_pose_kinematically():
    spec = DockSpec()
    dock = np.array([0.0, 0.0, 0.0])
    robot = compose(compose(dock, (spec.docked_offset + spec.staging_offset, 0.0, math.pi)), (0.1, 0.12, math.radians(15)))
    law, dt = DockApproach(spec), 0.05
    for _ in range(2000):
        v, w, done = law.step(compose(invert(robot), dock))
        if done:
            break
        robot = compose(robot, (v * dt, 0.0, w * dt))
    docked = compose(dock, (spec.docked_offset, 0.0, math.pi))
    assert done
    assert math.dist(robot[:2], docked[:2]) < 0.02
    assert abs(math.degrees(math.remainder(robot[2] - docked[2], 2 * math.pi))) < 2.0


def test_detects_the_dock_against_a_wall():
    spec = DockSpec()
    truth = np.array([1.0, 0.0, math.pi])  # apex 1 m ahead, opening toward the robot
    wall = np.c_[np.full(120, 1.04), np.linspace(-1.0, 1.0, 120)]  # the wall the dock stands against, just behind the apex
    pts = np.vstack([_v_points(truth, spec, noise=0.01), wall + np.random.default_rng(1).normal(0, 0.01, wall.shape)])
    det = detect_dock(pts, truth + np.array([-0.05, 0.06, 0.05]), spec)
    assert det.found, det.reason
    assert math.dist(det.pose[:2], truth[:2]) < 0.015 and abs(math.remainder(det.pose[2] - truth[2], 2 * math.pi)) < math.radians(2)
