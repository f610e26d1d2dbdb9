"""Checkers judged on hand-written histories: the fallback ladder's order and retries, the
stop-on-stale rule, recovery of a fault that must show a failure first, and faults cut short."""
import pytest

from emos.chaos.checkers import judge_faults, moving_again, stops_on_stale, verdict
from emos.chaos.history import History, Record
from emos.chaos.ladder import LadderSpecError, check_ladder, parse_spec

pytestmark = pytest.mark.unit

SPEC = parse_spec({"component": "solver", "steps": ["reset_state", "restart", "switch_algorithm"], "max_retries": 2}, "test")
ACTIONS = {1: "solver.reset_state()", 2: "restart(solver)", 3: "solver.switch_algorithm()"}


def _history(records):
    h = History()
    h._records = list(records)
    return h


def _attempts(pairs, t0=1.0, child="solver"):
    return [Record(t0 + 0.1 * i, "event", "fallback", {"child": child, "step": s, "attempt": a, "steps": 3, "of": 2, "action": ACTIONS[s]})
            for i, (s, a) in enumerate(pairs)]


def test_ladder_walked_in_order_twice_passes():
    walk = [(1, 1), (1, 2), (2, 1), (2, 2), (3, 1)]
    out = check_ladder(_history(_attempts(walk) + _attempts(walk, t0=5.0)), SPEC)
    assert out == {"episodes": 2, "attempts": 10, "complete": 2, "violations": []}


def test_ladder_skipping_a_retry_or_a_step_is_a_violation():
    out = check_ladder(_history(_attempts([(1, 1), (2, 1), (2, 2), (3, 1)])), SPEC)
    assert len(out["violations"]) == 1 and "step 2 try 1 followed step 1 try 1 (expected step 1 try 2)" in out["violations"][0]
    out = check_ladder(_history(_attempts([(1, 1), (1, 2), (3, 1)])), SPEC)
    assert "expected step 2 try 1" in out["violations"][0]


def test_ladder_wrong_action_wrong_retries_and_early_give_up_are_violations():
    recs = _attempts([(1, 1), (1, 2)])
    recs[1].detail["action"] = "restart(solver)"
    recs.append(Record(2.0, "event", "gave_up", {"child": "solver"}))
    out = check_ladder(_history(recs), SPEC)
    assert any("ran 'restart(solver)', declared 'reset_state'" in v for v in out["violations"])
    assert any("gave up after step (1, 2)" in v for v in out["violations"])
    recs = _attempts([(1, 1)])
    recs[0].detail["of"] = 3
    assert "declared 3 x 2" in check_ladder(_history(recs), SPEC)["violations"][0]
    # other components' ladders are not this one's
    assert check_ladder(_history(_attempts([(2, 2)], child="other")), SPEC)["attempts"] == 0


def test_ladder_spec_errors_name_the_problem():
    with pytest.raises(LadderSpecError, match="fallback_ladder must be"):
        parse_spec({"component": "x"}, "s.yaml")
    with pytest.raises(LadderSpecError, match="max_retries must be an int >= 1"):
        parse_spec({"component": "x", "steps": ["a"], "max_retries": 0}, "s.yaml")


def test_stop_on_stale_flags_a_moving_command_after_the_timeout_only():
    h = _history([Record(10.0, "fault", "sensor", {"stale": True, "topic": "/scan", "expects": "healthy", "target": "dm"}),
                  Record(12.0, "fault_end", "sensor", {"fault_t": 10.0}),
                  Record(20.0, "fault", "sensor", {"stale": False, "topic": "/scan", "expects": "healthy", "target": "dm"}),
                  Record(21.0, "fault_end", "sensor", {"fault_t": 20.0})])
    ok = [(10.2, 0.4), (10.5, 0.2), (10.6, 0.0), (11.9, 0.0), (12.1, 0.4), (20.7, 0.4)]  # moving before +0.55 s, after the end, or in a non-stale fault
    assert stops_on_stale(h, ok, within=0.55) == []
    bad = ok + [(11.0, 0.3)]
    (v,) = stops_on_stale(h, sorted(bad), within=0.55)
    assert v["fault_t"] == 10.0 and v["command_t"] == 11.0 and v["late_s"] == 1.0


def test_moving_again_counts_from_the_fault_or_the_end_of_a_ridden_out_fault_and_after_recovery():
    h = _history([Record(1.0, "status", "planner", {"pid": 5, "health": "HEALTHY"}),
                  Record(1.0, "fault", "kill", {"target": "planner", "pid": 5, "expects": "restart"}),
                  Record(1.6, "status", "planner", {"pid": 6, "health": "HEALTHY"}),
                  Record(3.0, "fault", "sensor", {"target": "planner", "expects": "healthy"}), Record(4.0, "fault_end", "sensor", {"fault_t": 3.0})])
    outcomes = judge_faults(h, {})
    # the command at 1.5 s was sent before the planner was back: not the recovery of motion
    assert moving_again(h, [(1.5, 0.2), (1.8, 0.2), (4.5, 0.3)], outcomes) == [800.0, 500.0]
    assert moving_again(h, [(1.5, 0.0)], outcomes) == [None, None]


def test_recover_needs_a_failure_then_healthy_and_its_witness():
    base = [Record(1.0, "status", "solver", {"pid": 5, "health": "HEALTHY"}),
            Record(2.0, "fault", "method", {"target": "solver", "expects": "recover", "witness": "/alarms"}),
            Record(2.1, "status", "solver", {"pid": 5, "health": "ALGORITHM_FAILURE"}),
            Record(3.0, "status", "solver", {"pid": 6, "health": "HEALTHY"})]
    (o,) = judge_faults(_history(base), {"/alarms": [2.2]})
    assert o.recovered and o.recover_ms == pytest.approx(1000.0)
    (o,) = judge_faults(_history(base), {"/alarms": [1.0]})  # the Monitor never raised the alarm
    assert not o.recovered
    (o,) = judge_faults(_history(base[:2] + base[3:]), {"/alarms": [2.2]})  # no failure seen: the fault missed
    assert not o.recovered


def test_a_fault_cut_short_by_the_end_of_the_run_is_not_judged():
    h = _history([Record(1.0, "status", "planner", {"pid": 5, "health": "HEALTHY"}),
                  Record(9.0, "fault", "kill", {"target": "planner", "pid": 5, "expects": "restart"}),
                  Record(9.5, "exit", "system", {"code": 0})])
    (o,) = judge_faults(h, {}, grace_s=3.0)
    assert o.cut and not o.recovered
    result = {"exit_code": 0, "faults": 1, "recovered": 0, "cut": 1, "outcomes": [{"nemesis": "kill", "t": 9.0, "target": "planner", "recovered": False, "cut": True}],
              "leaks": {"shm": 0, "procs": 0, "dirs": 0}, "zombies": 0, "corrupt": 0, "recover_ms": {"p95": None}}
    assert verdict(result, {}) == []
    assert verdict(result, {"min_faults": 2}) == ["only 1 fault(s) injected, expected >= 2"]
    (o,) = judge_faults(h, {}, grace_s=0.2)  # the run went on long enough: a real loss
    assert not o.cut
