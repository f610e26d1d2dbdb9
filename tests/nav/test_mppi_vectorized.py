"""MPPI's vectorized step (time-major float32 buffers, row loops instead of numpy's column
accumulations): the samples keep the robot's limits, the rollout is the unicycle stepped one
sample at a time, the optimal sequence keeps the asymmetric acceleration limits, and a seed
gives the same commands twice."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.controllers import MPPI, MPPIConfig
from emos.actors.nav.controllers.mppi import _cumsum_rows
from tests.nav.sim2d import make_robot

pytestmark = pytest.mark.unit


def _mppi(**kw) -> MPPI:
    robot = make_robot("DIFFERENTIAL_DRIVE", "BOX", (0.5, 0.43, 0.3))
    return MPPI(robot, MPPIConfig(batch_size=kw.pop("batch_size", 64), time_steps=kw.pop("time_steps", 20), **kw))


def test_row_cumsum_is_numpys():
    a = np.random.default_rng(1).normal(size=(2, 30, 17)).astype(np.float32)
    for axis in (0, 1, 2):
        b = a.copy()
        _cumsum_rows(b, axis=axis)
        np.testing.assert_array_equal(b, np.cumsum(a, axis=axis))


def test_samples_keep_the_speed_and_acceleration_limits():
    c = _mppi()
    velocity = np.array([0.3, 0.0, -0.4])
    c.u[:] = np.array([[5.0], [0.0], [-9.0]], dtype=np.float32)  # far beyond the limits
    v = c._v
    np.add(c.u[:, :, None], c.noise, out=v)
    c._limit_samples(v, velocity)
    vx_min, vx_max, _, wz_max = c.limits
    assert v[0].min() >= vx_min - 1e-6 and v[0].max() <= vx_max + 1e-6
    assert np.abs(v[2]).max() <= wz_max + 1e-6 and not v[1].any()
    dt = c.config.model_dt
    for axis, lim in ((0, c.robot.ctrl_vx_limits), (2, c.robot.ctrl_omega_limits)):
        step = min(lim.max_acc, lim.max_decel) * dt
        seq = np.concatenate([np.full((1, v.shape[2]), velocity[axis], dtype=np.float32), v[axis]])
        assert np.abs(np.diff(seq, axis=0)).max() <= step * (1 + 1e-5) + 1e-6


def test_the_optimal_sequence_speeds_up_by_max_acc_and_slows_by_max_decel():
    c = _mppi()
    lim = c.robot.ctrl_vx_limits
    dt = c.config.model_dt
    u = np.zeros((3, 20), dtype=np.float32)
    u[0, :10], u[0, 10:] = 5.0, -5.0  # full ahead, then full astern
    c._limit_sequence(u, np.zeros(3))
    steps = np.diff(np.concatenate([[0.0], u[0]]))
    vx_min, vx_max, _, _ = c.limits
    assert u[0].max() <= vx_max + 1e-6 and u[0].min() >= vx_min - 1e-6
    up = steps[:10]
    assert np.all(up <= lim.max_acc * dt + 1e-6) and up[0] == pytest.approx(min(lim.max_acc * dt, vx_max), rel=1e-5)
    down = steps[10:]
    # Slowing down from ahead is by max_decel; once reversing, speeding up astern by max_acc.
    assert np.all(down >= -max(lim.max_decel, lim.max_acc) * dt - 1e-6)


def test_the_batch_rollout_is_the_unicycle_stepped_sample_by_sample():
    c = _mppi(batch_size=5, time_steps=12)
    rng = np.random.default_rng(4)
    v = np.zeros((3, 12, 5), dtype=np.float32)
    v[0] = rng.uniform(-0.5, 1.5, (12, 5))
    v[2] = rng.uniform(-2.0, 2.0, (12, 5))
    pose = np.array([3.0, -2.0, 2.5])
    x, y, yaw = c._integrate(pose, v)
    dt = c.config.model_dt
    for k in range(5):
        px, py, th = pose
        for t in range(12):
            px += v[0, t, k] * math.cos(th) * dt
            py += v[0, t, k] * math.sin(th) * dt
            th += v[2, t, k] * dt
            assert (x[t, k], y[t, k], yaw[t, k]) == pytest.approx((px, py, th), abs=1e-4)


def test_a_seed_gives_the_same_commands():
    def run() -> list[np.ndarray]:
        c = _mppi(batch_size=200, time_steps=30, seed=7)
        xs = np.linspace(0.0, 4.0, 81)
        c.set_path(np.stack([xs, 0.2 * np.sin(xs)], 1))
        obstacles = np.array([[1.5, 0.6], [2.0, -0.7]])
        return [c.compute(np.array([0.1 * i, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]), obstacles).command for i in range(5)]

    for a, b in zip(run(), run()):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("value", [0.0, -0.05, 2.0])
def test_a_bad_distance_resolution_is_refused_by_name(value):
    with pytest.raises(ValueError, match="distance_resolution"):
        MPPIConfig(distance_resolution=value)
