"""Stuck detection and recovery, the one home (emos.actors.nav.stuck), on simulated time: the
progress checker, the navigator's back-out-then-block recovery, the Controller's stall hold,
and the in-process navigator driven through a stall twice without a simulator."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.navigator import GridNavigator, NavTask, Observation
from emos.actors.nav.robot import RobotConfig
from emos.actors.nav.stuck import BackOutThenBlock, ProgressChecker, Recovery, StallHold

pytestmark = pytest.mark.unit

DT = 0.1  # a 10 Hz control loop


def _times(start: float, stop: float) -> list[float]:
    return [round(start + DT * k, 6) for k in range(int(round((stop - start) / DT)) + 1)]


def test_a_robot_standing_still_is_stuck_once_per_timeout_and_progress_forgives_it():
    check = ProgressChecker(timeout=3.0, distance=0.3)
    stalls = [t for t in _times(0.0, 10.0) if check.update(t, 5.0)]
    assert stalls == [3.0, 6.0, 9.0]  # counting starts again after each stall
    check = ProgressChecker(timeout=3.0, distance=0.3)
    # Closing in at 0.2 m/s: 0.3 m of progress every 1.5 s, never stuck.
    assert not any(check.update(t, 10.0 - 0.2 * t) for t in _times(0.0, 20.0))
    # Creeping at 0.05 m/s: 0.15 m in 3 s is not enough.
    check = ProgressChecker(timeout=3.0, distance=0.3)
    assert [t for t in _times(0.0, 7.0) if check.update(t, 10.0 - 0.05 * t)] == [3.0, 6.0]


def test_unknown_distances_are_ignored_and_a_clock_that_went_back_starts_over():
    check = ProgressChecker(timeout=1.0, distance=0.1)
    assert not check.update(0.0, 4.0)
    assert not check.update(5.0, float("inf"))  # no plan: no judgement
    assert not check.update(5.0, float("nan"))
    assert check.update(5.0, 4.0)
    assert not check.update(1.0, 4.0)  # a restarted simulator: a new reference, no stall
    assert not check.update(1.9, 4.0) and check.update(2.0, 4.0)
    check.reset()
    assert not check.update(2.5, 4.0)
    with pytest.raises(ValueError, match="timeout and distance must be > 0"):
        ProgressChecker(3.0, 0.0)


def test_back_out_first_then_block_when_stuck_again_soon_after():
    rec = BackOutThenBlock(stuck_time=3.0, recovery_time=2.0)
    assert rec.escalate_within == 11.0  # 3 * stuck_time + recovery_time
    assert not rec.backing_out(0.0)
    assert rec.on_stall(3.0) is Recovery.BACK_OUT
    assert rec.backing_out(3.0) and rec.backing_out(4.99) and not rec.backing_out(5.0)
    assert rec.on_stall(8.0) is Recovery.BLOCK_AND_BACK_OUT  # 5 s after the last: the route is impossible
    assert rec.backing_out(9.9) and not rec.backing_out(10.0)
    assert rec.on_stall(18.99) is Recovery.BLOCK_AND_BACK_OUT
    assert rec.on_stall(30.0) is Recovery.BACK_OUT  # 11 s or more later: a new pocket, back out only
    rec.reset()
    assert rec.on_stall(31.0) is Recovery.BACK_OUT and rec.backing_out(31.0)
    with pytest.raises(ValueError, match="stuck_time must be > 0"):
        BackOutThenBlock(0.0, 2.0)


def test_a_stall_holds_until_the_robot_has_moved_away_from_it():
    hold = StallHold(release=0.1)
    assert not hold.holding((0.0, 0.0))
    hold.hold(np.array([1.0, 2.0, 0.5])[:2])
    assert hold.holding((1.0, 2.0)) and hold.holding((1.05, 2.05))
    assert not hold.holding((1.1, 2.0))  # moved 0.1 m: released ...
    assert not hold.holding((1.0, 2.0))  # ... for good, even back at the spot
    hold.hold((0.0, 0.0))
    hold.clear()
    assert not hold.holding((0.0, 0.0))


def _task() -> NavTask:
    robot = RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([0.508, 0.43, 0.25]))
    return NavTask(robot, start=(0.0, 0.0, 0.0), goal=(4.0, 0.0), goal_radius=0.3, scan_mount=(0.0, 0.0, 0.0),
                   control_rate_hz=1 / DT)


def test_the_in_process_navigator_backs_out_then_blocks_the_route_when_it_cannot_move():
    # A robot whose wheels do nothing (the pose never changes) in an empty world: the plan is
    # straight to the goal, the cost-to-go never drops.
    nav = GridNavigator(localize=False)
    nav.reset(_task())
    pose, still = np.zeros(3), np.zeros(3)
    backing: list[float] = []
    blocks_at: list[tuple[float, int]] = []
    for t in _times(0.0, 12.0):
        if nav.update(Observation(t, pose, still, None)):
            backing.append(t)
        if not blocks_at or blocks_at[-1][1] != len(nav.virtual_blocks):
            blocks_at.append((t, len(nav.virtual_blocks)))
    # Stuck at 3 s: back out for 2 s, no block. Stuck again at 6 s (soon after): block the
    # plan's tightest spot and back out again; and again at 9 and 12 s.
    assert backing[0] == 3.0 and 4.9 in backing and 5.0 not in backing
    assert 6.0 in backing and 7.9 in backing and 8.0 not in backing
    assert blocks_at == [(0.0, 0), (6.0, 1), (9.0, 2), (12.0, 3)]
    # Waiting with progress: a fresh run is not stuck before stuck_time.
    nav.reset(_task())
    assert not any(nav.update(Observation(t, pose, still, None)) for t in _times(0.0, 2.9))
