"""The swept check's C inner loop (actors/nav/safety/_cswept.c) answers as the numpy one does:
over random scans and commands (box and round robots, histories, leads), over the inner loop's
own arguments (shared poses, a decisive candidate, points far and near), and it refuses
arrays of the wrong shape with an error instead of reading outside them."""
from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig
from emos.actors.nav.safety import swept as swept_module
from emos.actors.nav.safety.swept import SweptConfig, SweptFootprint

pytestmark = [pytest.mark.unit, pytest.mark.skipif(
    swept_module.NATIVE is None, reason="the C inner loop is not built (no compiler at install, or EMOS_SWEPT=python)")]


def _robot(shape: str) -> RobotConfig:
    if shape == "box":
        return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([0.458, 0.4156, 0.282]),
                           ctrl_vx_limits=LinearCtrlLimits(max_vel=2.0, max_acc=20.0, max_decel=20.0),
                           ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=25.0, max_decel=25.0))
    return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="CYLINDER", geometry_params=np.array([0.25, 0.3]),
                       ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=3.0, max_decel=5.0),
                       ctrl_omega_limits=AngularCtrlLimits(max_vel=2.0, max_acc=6.0, max_decel=8.0))


def _pair(shape: str, config: SweptConfig | None = None) -> tuple[SweptFootprint, SweptFootprint]:
    robot = _robot(shape)
    return SweptFootprint(robot, config, native=False), SweptFootprint(robot, config, native=True)


def _posts(rng: np.random.Generator, count: int, near: float) -> np.ndarray:
    """Scan points on the outlines of round posts, some as near as ``near`` m to the centre."""
    centres = rng.uniform(-2.5, 2.5, (count, 2))
    centres = centres[np.hypot(centres[:, 0], centres[:, 1]) > near]
    angles = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
    return np.concatenate([c + 0.075 * np.c_[np.cos(angles), np.sin(angles)] for c in centres])


@pytest.mark.parametrize("shape", ["box", "round"])
@pytest.mark.parametrize("config", [SweptConfig(), SweptConfig(hysteresis=0.02, latency=0.3, max_gains=9, margin=0.05)],
                         ids=["default", "wide"])
def test_check_answers_alike_over_random_scans_and_commands(shape, config):
    numpy_check, c_check = _pair(shape, config)
    rng = np.random.default_rng(8801 if shape == "box" else 8802)
    answers = set()
    for scan_index in range(6):
        points = _posts(rng, 40 + 10 * scan_index, 0.3 + 0.03 * scan_index)
        prepared = numpy_check.prepare(points), c_check.prepare(points)
        for n in range(60):
            command = np.array([rng.uniform(-0.6, 2.0), 0.0, rng.uniform(-3.5, 3.5)])
            if n % 6 == 0:
                command[0] = 0.0  # rotations in place
            previous = np.clip(command + rng.normal(0.0, 0.4, 3), -3.0, 3.0) * np.array([1.0, 0.0, 1.0])
            history = None
            if n % 3 == 1:
                times = np.sort(rng.uniform(-0.4, 0.0, 5))
                history = (times, np.c_[rng.uniform(-0.5, 2.0, 5), np.zeros(5), rng.uniform(-3.0, 3.0, 5)])
            lead = float(rng.uniform(0.0, 0.2))
            a = numpy_check.check(command, previous, prepared[0], lead=lead, history=history)
            b = c_check.check(command, previous, prepared[1], lead=lead, history=history)
            assert (a.scale, a.blocked) == (b.scale, b.blocked), (scan_index, n, a, b)
            assert b.clearance == pytest.approx(a.clearance, abs=1e-9), (scan_index, n, a, b)
            answers.add((a.scale, a.blocked))
    # Not a vacuous comparison: let through, slowed, stopped and blocked all occurred.
    assert {s for s, _ in answers} >= {0.0, 1.0} and len({s for s, _ in answers}) >= 3
    assert any(blocked for _, blocked in answers)


def _random_poses(rng: np.random.Generator, candidates: int, gains: int, steps: int) -> np.ndarray:
    """Poses (C, G, K, 3) of random arcs from the origin, as SweptFootprint.poses makes them."""
    twists = np.zeros((candidates, steps, 3))
    twists[..., 0] = rng.uniform(-0.5, 1.5, (candidates, 1))
    twists[..., 2] = rng.uniform(-3.0, 3.0, (candidates, 1))
    twists[:, steps // 2:] *= np.linspace(1.0, 0.0, steps - steps // 2)[None, :, None]
    return SweptFootprint(_robot("box")).poses(twists, np.linspace(0.6, 1.1, gains))


@pytest.mark.parametrize("shape", ["box", "round"])
def test_the_inner_loop_answers_alike_for_every_kind_of_batch(shape):
    numpy_check, c_check = _pair(shape)
    rng = np.random.default_rng(8803)
    outcomes = set()
    for trial in range(150):
        candidates, gains, steps = 1 + trial % 4, 1 + trial % 5, 3 + (trial * 7) % 60
        poses = _random_poses(rng, candidates, gains, steps)
        points = numpy_check.prepare(_posts(rng, 30, 0.25 + 0.1 * (trial % 4)) if trial % 10 else np.zeros((0, 2)))
        homog, norm2, start = points.homog, points.norm2, points.start
        limits = rng.uniform(0.02, 0.12, candidates)
        travel = rng.uniform(0.0, 0.2, candidates)
        shared = [-1, 0, 2, 5, 11, steps + 3][trial % 6]
        decisive = None if trial % 3 else 0
        args = (poses, homog, norm2, start, limits, travel, shared, 0.05, decisive)
        expected, got = numpy_check._touches(*args), c_check._touches(*args)
        assert len(expected) == len(got) == candidates
        for e, g in zip(expected, got):
            assert (e is None) == (g is None), (trial, expected, got)
            if e is not None:
                assert (e[0], e[2], e[3]) == (g[0], g[2], g[3]), (trial, expected, got)
                assert g[1] == pytest.approx(e[1], abs=1e-9), (trial, expected, got)
                outcomes.add((e[0], e[2], e[3]))
    assert len(outcomes) >= 4  # touches or not, early or not, head clear or not: several mixes met


def test_wrong_shapes_are_refused_not_read_past():
    check = SweptFootprint(_robot("box"), native=True)
    good = check.prepare(np.array([[0.5, 0.0], [1.0, 0.2]]))
    poses = np.zeros((1, 2, 5, 3))
    one = np.array([0.05])
    native = swept_module.NATIVE
    with pytest.raises(ValueError, match="homog"):
        native.touches(poses, good.homog[:2], good.norm2, good.start, one, one, 0, 0.05, -1, check._native_shape)
    with pytest.raises(ValueError, match="norm2 and start"):
        native.touches(poses, good.homog, good.norm2[:1], good.start, one, one, 0, 0.05, -1, check._native_shape)
    with pytest.raises(ValueError, match="limits and steps"):
        native.touches(poses, good.homog, good.norm2, good.start, np.array([0.05, 0.05]), one, 0, 0.05, -1, check._native_shape)
    with pytest.raises(ValueError, match="decisive"):
        native.touches(poses, good.homog, good.norm2, good.start, one, one, 0, 0.05, 1, check._native_shape)
    with pytest.raises(ValueError, match="poses must be a 4-d"):
        native.touches(np.zeros((2, 5, 3)), good.homog, good.norm2, good.start, one, one, 0, 0.05, -1, check._native_shape)


def test_emos_swept_python_turns_the_c_loop_off():
    env = dict(os.environ, EMOS_SWEPT="python")
    out = subprocess.run([sys.executable, "-c", "from emos.actors.nav.safety import swept; print(swept.NATIVE)"],
                         env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "None"


def test_native_true_without_the_module_says_what_is_missing(monkeypatch):
    monkeypatch.setattr(swept_module, "NATIVE", None)
    with pytest.raises(RuntimeError, match="_cswept.c was not built"):
        SweptFootprint(_robot("box"), native=True)
    assert SweptFootprint(_robot("box"))._native is None  # the default falls back to numpy


@pytest.mark.parametrize("native", [False, True], ids=["numpy", "c"])
def test_points_that_are_not_finite_are_no_obstacle(native):
    check = SweptFootprint(_robot("box"), native=native)
    near = np.array([[0.45, 0.0]])  # ahead, within reach of a forward command
    bad = np.array([[np.nan, 0.1], [np.inf, 0.0], [0.3, -np.inf]])
    prepared = check.prepare(np.concatenate([bad, near]))
    assert len(prepared) == 1
    command = np.array([1.0, 0.0, 0.0])
    with_bad = check.check(command, np.zeros(3), prepared)
    alone = check.check(command, np.zeros(3), near)
    assert (with_bad.scale, with_bad.blocked) == (alone.scale, alone.blocked) and with_bad.scale < 1.0
    assert math.isfinite(with_bad.clearance) and with_bad.clearance == alone.clearance
    assert check.check(command, np.zeros(3), bad).scale == 1.0
