"""Stuck recovery through the product: the Controller's progress checker reports a stall, the
recipe's fallback ladder backs out with the DriveManager and blocks the plan's tightest spot
in the Planner, and gives up (reported) when the ladder is spent. Real processes, real
pybullet worlds (the BARN stack of ``emos bench barn``)."""
from __future__ import annotations

import pytest

from emos.actors.sim.barn_worlds import load_barn_worlds
from emos.tools.barn.harness import BarnRules
from emos.tools.barn.process import run_episode_process
from emos.tools.barn.stack import RecoveryOptions, StackOptions, build_system

pytestmark = pytest.mark.sim


def test_the_stack_wires_the_recovery_ladder_on_the_controller():
    _, (mapper, planner, controller, driver) = build_system(StackOptions(world=3, rules=BarnRules(ideal=True)))
    assert controller.config.progress_timeout == 3.0 and controller.config.failure_tolerance == 3.0
    ladder = controller.fallbacks["on_algorithm_fail"]
    assert [a.describe() for a in ladder.steps[:2]] == ["driver.move_backward()", "planner.block_tightest_spot()"]
    assert len(ladder.steps) == 2 * RecoveryOptions().attempts and ladder.max_retries == 1
    assert "on_giveup" in controller.fallbacks
    _, (_, _, bare, _) = build_system(StackOptions(world=3, recovery=RecoveryOptions(enabled=False)))
    assert bare.config.progress_timeout == 0.0 and not bare.fallbacks


def test_a_robot_stuck_in_a_dead_end_backs_out_and_reaches_the_goal(tmp_path):
    # BARN world 242: the route up the right looks open from the start and ends in a dead end
    # the lidar only reveals from inside. Process-mode trials are not reproducible to the tick
    # (which of two consumers' outputs a step sees within a tick varies): a run may see the
    # dead end early enough not to stall, so several runs for one that stalls. A stalled run
    # must back out (the ladder's first step) and then reach the goal. Known limits of the
    # navigation on this world through the processes: about 1 stalled run in 8 times out (the
    # re-plan after the back-out leads into the same dead end again), and about 1 in 20 collides
    # (a contact with a cylinder near (-0.52, 6.52) after back-outs and blocks). Both are
    # navigation defects this test does not hide: each is logged with its run's tail, and three
    # failed stalled runs fail the test (under 1 % at those rates), as does a recovery that does
    # not work (every run fails).
    failures = []
    stalled = False
    for attempt in range(5):
        log = tmp_path / f"system{attempt}.log"
        result = run_episode_process(load_barn_worlds()[242], StackOptions(world=242, rules=BarnRules(ideal=True)),
                                     wall_timeout=240.0, keep_log=log)
        text = log.read_text(errors="replace")
        if "no progress" not in text:
            assert result.success, (result, text[-3000:])
            continue
        stalled = True
        assert "fallback driver.move_backward() reports recovery" in text, text[-3000:]
        if result.success:
            return
        failures.append(result)
        print(f"world 242, stalled run {attempt} failed (a known limit, see above): {result.reason}\n{text[-1500:]}")
        assert len(failures) < 3, (failures, text[-3000:])  # three times is not the known rates
    if not stalled:
        raise AssertionError("world 242 never stalled in five runs: the progress checker did not fire")
    raise AssertionError(f"no stalled run reached the goal: {failures}")


def test_the_recovery_gives_up_after_its_budget_and_reports_it(tmp_path):
    # A progress checker no robot can satisfy (5 m in 0.5 s): every half second is a stall, so
    # the ladder (one back-out, one block; steps up to 20 per s) is spent early in the trial.
    log = tmp_path / "system.log"
    recovery = RecoveryOptions(progress_timeout=0.5, progress_distance=5.0, attempts=1, rate=20.0)
    run_episode_process(load_barn_worlds()[3], StackOptions(world=3, rules=BarnRules(ideal=True), recovery=recovery),
                        wall_timeout=240.0, keep_log=log)
    text = log.read_text(errors="replace")
    steps = [line for line in text.splitlines() if "fallback handler=on_algorithm_fail" in line]
    assert [s.split("action=")[1].split()[0] for s in steps] == ["driver.move_backward()", "planner.block_tightest_spot()"], text[-3000:]
    assert "fallbacks exhausted (on_algorithm_fail" in text, text[-3000:]
    assert "stuck recovery spent" in text, text[-3000:]
