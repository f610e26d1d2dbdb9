"""Trials under the protocol: realistic and ideal configurations, seeds, charged compute."""
import time

import numpy as np
import pytest

from emos.actors.sim.barn_protocol import summarize_trials, trial_seed
from emos.actors.sim.barn_trial import TrialSpec, build_trial, run_trial
from emos.actors.sim.barn_worlds import BarnWorld
from emos.actors.sim.dynabarn import load_dynabarn

pytestmark = pytest.mark.sim

EMPTY = BarnWorld(idx=42, cylinders=np.zeros((0, 2)), path_length=10.0)


def straight(speed):
    def policy(stamp, odom, scan):
        return (speed, 0.0, 0.0)
    return policy


def _run(entry, policy, spec, seed=0):
    trial = build_trial(entry, seed, spec)
    try:
        return run_trial(trial, policy, spec, seed), trial
    finally:
        trial.close()


def test_realistic_trial_drives_the_skid_steer_jackal_with_its_sensors():
    seen = {}

    def policy(stamp, odom, scan):
        seen.setdefault("scan", scan)
        seen["odom"] = odom
        return (1.0, 0.0, 0.0)

    result, trial = _run(EMPTY, policy, TrialSpec())
    assert trial.robot.spec.name == "jackal-barn" and trial.robot.drive.name == "skid-steer"
    assert len(seen["scan"].ranges) == 720 and type(trial.odometry).__name__ == "WheelImuOdometry"
    assert result.success and result.world == 42
    # 9 m to the goal circle at 1 m/s; the official clock starts after the first 0.1 m.
    assert result.time_s == pytest.approx(8.95, abs=0.15)
    assert result.metric == pytest.approx(5.0 / 10.0) and result.metric_4t == pytest.approx(5.0 / 20.0)
    assert 0.6 <= result.yaw_gain <= 1.0
    assert result.control_steps > 80 and result.deadline_misses == 0


def test_ideal_trial_is_the_old_configuration():
    result, trial = _run(EMPTY, straight(1.0), TrialSpec(ideal=True))
    assert trial.robot.spec.name == "jackal" and trial.robot.drive.name == "ideal"
    assert len(trial.lidar.latest.ranges) == 1081
    assert result.success and result.yaw_gain is None and result.control_steps == 0


def test_seeds_draw_different_yaw_gains():
    gains = {_run(EMPTY, straight(0.0), TrialSpec(time_limit=0.5), trial_seed(42, i))[0].yaw_gain for i in range(4)}
    assert len(gains) == 4


def test_slow_policy_is_charged_and_its_deadline_misses_counted():
    def slow(stamp, odom, scan):
        end = time.thread_time() + 0.12  # CPU time: a loaded machine does not change the charge
        while time.thread_time() < end:
            pass
        return (1.0, 0.0, 0.0)

    spec = TrialSpec(time_limit=1.0)
    result, trial = _run(EMPTY, slow, spec)
    assert result.timeout
    assert result.deadline_misses == result.control_steps >= 8
    fast, fast_trial = _run(EMPTY, straight(1.0), spec)
    assert fast.deadline_misses == 0
    # The slow policy's commands act >= 0.12 s late: the official clock (first 0.1 m of
    # motion) started that much later.
    started = trial.world.clock.now() - result.time_s
    fast_started = fast_trial.world.clock.now() - fast.time_s
    assert started - fast_started == pytest.approx(0.13, abs=0.02)


def test_dynabarn_trial_scores_with_the_20_m_path():
    entry = load_dynabarn()[0]
    result, trial = _run(entry, straight(0.0), TrialSpec(time_limit=2.0))
    assert result.world == "dynabarn:0" and result.timeout and not result.collided
    assert trial.path_length == 20.0 and len(trial.world.movers) == 4
    s = summarize_trials([result])
    assert s["timeout_rate"] == 1.0 and s["deadline_misses"] == 0


def test_bad_spec_is_refused():
    with pytest.raises(ValueError, match="robot"):
        TrialSpec(robot="turtlebot3")
    with pytest.raises(ValueError, match="control_rate_hz"):
        TrialSpec(control_rate_hz=0.0)


def test_free_compute_runs_are_reproducible():
    spec = TrialSpec(charge_compute=False)
    a, _ = _run(EMPTY, straight(1.0), spec, seed=5)
    b, _ = _run(EMPTY, straight(1.0), spec, seed=5)
    assert a == b and a.control_steps == 0
