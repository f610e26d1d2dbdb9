"""The BARN protocol helpers: timer, outcomes, scores, seeds, charged compute time."""
import numpy as np
import pytest

from emos.actors.sim.barn_protocol import (
    ControlDeadline,
    MotionTimer,
    Trial,
    TrialMonitor,
    TrialOutcome,
    per_world,
    summarize_trials,
    trial_seed,
    tuning_split,
)
from emos.actors.sim.barn_worlds import barn_metric

pytestmark = pytest.mark.sim


def test_timer_starts_after_a_tenth_of_a_metre():
    timer = MotionTimer((0.0, 0.0))
    timer.update(1.0, (0.05, 0.0))
    assert timer.elapsed(2.0) == 0.0
    timer.update(3.0, (0.0, 0.1))
    assert timer.started_at == 3.0
    timer.update(4.0, (0.0, 0.0))  # coming back does not restart it
    assert timer.elapsed(10.0) == pytest.approx(7.0)


def test_monitor_outcomes():
    goal = (0.0, 10.0)
    m = TrialMonitor((0.0, 0.0), goal)
    assert m.update(0.5, (0.0, 0.0), False) is None
    assert m.update(2.0, (0.0, 0.5), False) is None  # timer started at 2.0
    out = m.update(6.0, (0.0, 9.05), False)
    assert out == TrialOutcome(True, False, False, 4.0, 6.0) and out.success
    assert m.update(7.0, (5.0, 5.0), True) is out  # over is over

    hit = TrialMonitor((0.0, 0.0), goal)
    hit.update(1.0, (0.0, 0.2), False)
    assert hit.update(1.5, (0.0, 0.9), True) == TrialOutcome(False, True, False, 0.5, 1.5)

    slow = TrialMonitor((0.0, 0.0), goal, time_limit=5.0)
    slow.update(1.0, (0.0, 0.2), False)
    assert slow.update(5.5, (0.0, 1.0), False) is None  # 4.5 s on the official clock
    assert slow.update(6.0, (0.0, 1.0), False).timeout

    still = TrialMonitor((0.0, 0.0), goal, time_limit=5.0)
    out = still.update(5.0, (0.0, 0.0), False)
    assert out.timeout and out.time_s == 5.0


def test_both_metrics():
    ol = 10.0  # OT = 5 s
    assert barn_metric(True, 8.0, ol) == pytest.approx(0.5)
    assert barn_metric(True, 8.0, ol, low=4.0) == pytest.approx(0.25)
    assert barn_metric(True, 25.0, ol) == pytest.approx(0.2)
    assert barn_metric(True, 25.0, ol, low=4.0) == pytest.approx(0.2)
    t = Trial.scored(3, 7, TrialOutcome(True, False, False, 12.0, 13.0), ol)
    assert (t.metric, t.metric_4t) == (pytest.approx(5 / 12), pytest.approx(0.25))
    dyn = Trial.scored("dynabarn:0", 0, TrialOutcome(True, False, False, 30.0, 31.0), 20.0)
    assert dyn.metric == pytest.approx(10 / 30)  # the correct 20 m path, not DynaBARN's 0.125 for all


def test_summaries_per_world_and_split():
    def trial(world, ok, collided=False, time_s=10.0, misses=0):
        return Trial.scored(world, 0, TrialOutcome(ok, collided, not ok and not collided, time_s, time_s), 10.0,
                            yaw_gain=0.8) if not misses else attrs_with_misses(world, ok, time_s, misses)

    def attrs_with_misses(world, ok, time_s, misses):
        d = ControlDeadline(0.1, 0.01)
        for _ in range(misses):
            d.delay_ticks(0.2)
        return Trial.scored(world, 0, TrialOutcome(ok, False, not ok, time_s, time_s), 10.0, deadline=d)

    trials = [trial(1, True, time_s=10.0), trial(1, False, collided=True), trial(5, True, time_s=20.0),
              trial(5, False, misses=2)]
    s = summarize_trials(trials)
    assert s["trials"] == 4
    assert (s["success_rate"], s["collision_rate"], s["timeout_rate"]) == (0.5, 0.25, 0.25)
    assert s["mean_time_s"] == 15.0
    assert s["mean_metric"] == pytest.approx((0.5 + 0.25) / 4, abs=1e-4)
    assert s["deadline_misses"] == 2
    pw = per_world(trials)
    assert list(pw) == [1, 5] and pw[1]["success_rate"] == 0.5
    split = tuning_split(trials)
    assert split["tune"]["trials"] == 2 and split["report"]["trials"] == 2
    assert trials[0].as_json()["yaw_gain"] == 0.8
    assert summarize_trials([])["trials"] == 0


def test_trial_seeds_differ_and_are_stable():
    seeds = {trial_seed(w, i) for w in (1, 2, "dynabarn:1") for i in range(10)}
    assert len(seeds) == 30
    assert trial_seed(7, 3) == trial_seed(7, 3)
    assert trial_seed(7, 3, base=1) != trial_seed(7, 3)


def test_control_deadline_charges_compute_time():
    d = ControlDeadline(period=0.1, tick=0.01)
    assert d.delay_ticks(0.0) == 0
    assert d.delay_ticks(0.004) == 1  # acts at the next tick
    assert d.delay_ticks(0.03) == 3
    assert d.delay_ticks(0.15) == 15  # a miss: later than the next control step
    assert (d.steps, d.misses) == (4, 1)
    assert d.worst_s == pytest.approx(0.15)
    slow_robot = ControlDeadline(period=0.1, tick=0.01, speed=0.5)  # the robot's computer is half as fast
    assert slow_robot.delay_ticks(0.06) == 12 and slow_robot.misses == 1
    with pytest.raises(ValueError, match="compute time"):
        d.delay_ticks(float("nan"))


def test_a_skid_steer_run_scored_end_to_end(make_world):
    """A scripted drive straight to a goal 6 m ahead: official time excludes the first 0.1 m."""
    from emos.actors.sim.barn_protocol import TrialMonitor

    world = make_world(ground=False, seed=1)
    robot = world.add_robot("jackal-barn", (0.0, 0.0, np.pi / 2))
    monitor = TrialMonitor((0.0, 0.0), (0.0, 6.0))
    outcome = None
    while outcome is None:
        robot.command(1.0, 0.0, 0.0)
        world.step()
        outcome = monitor.update(world.clock.now(), robot.pose[:2], robot.collided)
    assert outcome.success
    assert monitor.timer.started_at > 0.1  # lag and friction: moving 0.1 m takes a while
    assert outcome.time_s == pytest.approx(outcome.sim_time_s - monitor.timer.started_at)
    assert outcome.time_s == pytest.approx(4.9, abs=0.15)
