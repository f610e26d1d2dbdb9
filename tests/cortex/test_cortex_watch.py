"""What Cortex, as the launcher's monitor, makes of the run's streams (pure: no processes)."""
from __future__ import annotations

import json

import pytest

from emos.actors.agents.logic.cortex_watch import (
    RecoveryBudget,
    from_event_outcome,
    from_status,
    from_supervisor_event,
    recovery_task,
)
from emos.launcher import Launcher
from emos.msgs.status import ComponentStatus

pytestmark = pytest.mark.unit


def _status(level: int, message: str = "", algorithms: tuple[str, ...] = ()) -> ComponentStatus:
    return ComponentStatus(status=level, message=message, src_algorithms=list(algorithms))


def test_health_changes_are_observed_and_failures_are_trouble():
    assert from_status("arm", None, _status(0)) is None  # healthy from the start: nothing to say
    ill = from_status("arm", "HEALTHY", _status(1, "joint 3 stuck", ("ik",)))
    assert ill.trouble and ill.kind == "health" and ill.text == "component 'arm' health HEALTHY -> ALGORITHM_FAILURE (ik): joint 3 stuck"
    assert from_status("arm", "ALGORITHM_FAILURE", _status(1)) is None  # no change
    well = from_status("arm", "ALGORITHM_FAILURE", _status(0))
    assert not well.trouble and "-> HEALTHY" in well.text


def test_supervisor_events_become_observations_and_its_own_are_ignored():
    known = {"arm", "base"}
    crash = from_supervisor_event({"event": "exit", "child": "arm", "reason": "crash", "detail": "exit code 3"}, "cortex", known)
    assert crash.trouble and crash.component == "arm" and "exited (crash)" in crash.text
    asked = from_supervisor_event({"event": "exit", "child": "arm", "reason": "restart_requested", "by": "requested"}, "cortex", known)
    assert not asked.trouble
    assert from_supervisor_event({"event": "exit", "child": "cortex", "reason": "crash"}, "cortex", known) is None
    assert from_supervisor_event({"event": "escalated", "supervisor": "cortex_monitor"}, "cortex", known) is None
    assert from_supervisor_event({"event": "started", "child": "arm"}, "cortex", known) is None
    gave_up = from_supervisor_event({"event": "gave_up", "child": "base", "level": "COMPONENT_FAILURE"}, "cortex", known)
    assert gave_up.trouble and "exhausted on COMPONENT_FAILURE" in gave_up.text
    result = from_supervisor_event({"event": "fallback_result", "child": "base", "action": "restart(base)", "ok": False,
                                    "detail": "TimeoutError"}, "cortex", known)
    assert result.trouble and "FAILED: TimeoutError" in result.text
    # Garbage from the log is ignored, and what is echoed is made printable.
    assert from_supervisor_event("nonsense", "cortex", known) is None
    odd = from_supervisor_event({"event": "exit", "child": "arm", "reason": "crash", "detail": "a\x1b[2Jb"}, "cortex", known)
    assert "\x1b" not in odd.text


def test_event_outcomes_give_one_observation_per_failed_action():
    record = {"event": "Event(battery < 10)", "topic": "/battery", "actions": [
        {"action": "dock()", "component": "base", "ok": False, "detail": "failed: RuntimeError: no dock"},
        {"action": "say()", "component": "voice", "ok": True}]}
    [failed] = from_event_outcome(json.dumps(record))
    assert failed.trouble and failed.component == "base" and "no dock" in failed.text
    assert from_event_outcome("{not json") == [] and from_event_outcome(json.dumps({"actions": "x"})) == []


def test_the_recovery_budget_bounds_plans_per_component_and_window():
    budget = RecoveryBudget(2, 60.0)
    assert budget.allow("arm", 0.0) and budget.allow("arm", 1.0) and not budget.allow("arm", 2.0)
    assert budget.allow("base", 2.0)  # per component
    assert budget.allow("arm", 61.5)  # the window moved on
    task = recovery_task("arm", [from_status("arm", "HEALTHY", _status(2, "driver lost"))])
    assert task.splitlines()[0] == "RECOVER component 'arm': the system reports a problem." and "driver lost" in task


def test_the_launcher_takes_a_monitor_only_if_it_can_serve_as_one():
    from emos.core.component import BaseComponent

    launcher = Launcher()
    plain = BaseComponent(component_name="plain")
    with pytest.raises(TypeError, match="serve_as_monitor"):
        launcher.add_pkg(components=[BaseComponent(component_name="a")], monitor=plain)

    class Watcher(BaseComponent):
        def serve_as_monitor(self, outcomes_topic=None):
            self.outcomes = outcomes_topic

    watcher = Watcher(component_name="watcher")
    with pytest.raises(ValueError, match="pass it as monitor= only"):
        launcher.add_pkg(components=[watcher], monitor=watcher)
    launcher.add_pkg(components=[BaseComponent(component_name="b")], monitor=watcher)
    with pytest.raises(ValueError, match="has a monitor already"):
        launcher.add_pkg(components=[BaseComponent(component_name="c")], monitor=Watcher(component_name="other"))
    package = launcher._monitor_package()
    assert package.name == "watcher_monitor" and package.components == [watcher] and package.group_restart.value == "temporary"
    assert watcher.outcomes == "emos_monitor/outcomes"
