"""What Cortex sees when it serves as the launcher's monitor (``add_pkg(monitor=cortex)``).

Three streams become :class:`Observation` s (pure functions here; the component reads them):

* the components' health, from each one's ``<component>/status`` (a change of level);
* the supervisor's event log (``SUPERVISOR_EVENTS``): exits, crashes, failed starts,
  escalations, fallback attempts, their results and give-ups;
* the Monitor's event outcomes (``emos_monitor/outcomes``): each fired event's actions, ok or not.

An observation that is ``trouble`` may start a recovery task (:func:`recovery_task`), planned
with the same tools as any task, within :class:`RecoveryBudget` (per component, per window).
"""
from __future__ import annotations

import collections
import json
from typing import Any

import attrs

from emos.core.discovery import printable

# Health levels by value (emos.core.health.HealthLevel; kept as names, so this module stays pure).
_LEVELS = {0: "HEALTHY", 1: "ALGORITHM_FAILURE", 2: "COMPONENT_FAILURE", 3: "SYSTEM_FAILURE", 4: "GENERAL"}
_FAILING = {"ALGORITHM_FAILURE", "COMPONENT_FAILURE", "SYSTEM_FAILURE"}
_ABNORMAL_EXITS = {"crash", "killed", "hang", "start_failed"}


@attrs.frozen
class Observation:
    component: str
    kind: str  # health, exit, start_failed, escalated, fallback, fallback_result, gave_up, event
    text: str
    trouble: bool = False

    def asdict(self) -> dict[str, Any]:
        return attrs.asdict(self)


def level_name(status: int) -> str:
    return _LEVELS.get(int(status), f"LEVEL_{int(status)}")


def from_status(component: str, previous: str | None, status: Any) -> Observation | None:
    """A health change of ``component`` (``previous`` level name -> this ComponentStatus), or None."""
    level = level_name(getattr(status, "status", 0))
    if level == previous or (previous is None and level == "HEALTHY"):
        return None
    message = printable(str(getattr(status, "message", "") or ""), 200)
    what = [*getattr(status, "src_algorithms", ()), *getattr(status, "src_components", ()), *getattr(status, "src_topics", ())]
    detail = f" ({', '.join(printable(str(w), 60) for w in what[:5])})" if what else ""
    text = f"component '{component}' health {previous or 'unknown'} -> {level}{detail}" + (f": {message}" if message else "")
    return Observation(component, "health", text, trouble=level in _FAILING)


def from_supervisor_event(event: Any, me: str, components: set[str]) -> Observation | None:
    """One record of the supervisor's event log, or None if it says nothing worth watching
    (starts, stops; anything about ``me``; groups' own bookkeeping)."""
    if not isinstance(event, dict):
        return None
    kind = event.get("event")
    child = printable(str(event.get("child", "") or ""), 120)
    detail = printable(str(event.get("detail", "") or ""), 200)
    if child == me or (kind == "escalated" and str(event.get("supervisor", "")).startswith(f"{me}_")):
        return None  # our own restarts are the supervisor's business, not a plan's
    if kind == "exit" and child in components:
        reason = printable(str(event.get("reason", "")), 40)
        by = printable(str(event.get("by", "") or ""), 40)
        text = f"component '{child}' exited ({reason}{', by ' + by if by else ''})" + (f": {detail}" if detail else "")
        return Observation(child, "exit", text, trouble=reason in _ABNORMAL_EXITS)
    if kind == "start_failed" and child in components:
        return Observation(child, "start_failed", f"component '{child}' failed to start: {detail}", trouble=True)
    if kind == "escalated":
        group = printable(str(event.get("supervisor", "")), 120)
        return Observation(group, "escalated", f"group '{group}' gave up restarting its components: {detail}", trouble=False)
    if kind == "fallback" and child in components:
        text = (f"fallback of '{child}': {printable(str(event.get('action', '')), 120)} "
                f"(attempt {event.get('attempt')} of {event.get('of')}, level {event.get('level')})")
        return Observation(child, "fallback", text)
    if kind == "fallback_result" and child in components:
        ok = bool(event.get("ok"))
        text = f"fallback of '{child}' {printable(str(event.get('action', '')), 120)}: {'done' if ok else 'FAILED'}" + (f": {detail}" if detail else "")
        return Observation(child, "fallback_result", text, trouble=not ok)
    if kind == "gave_up" and child in components:
        return Observation(child, "gave_up", f"fallbacks of '{child}' exhausted on {event.get('level')}: the supervisor gave up", trouble=True)
    return None


def from_event_outcome(data: str) -> list[Observation]:
    """The Monitor's report of one fired event (JSON): one observation per failed action."""
    try:
        record = json.loads(data)
    except (TypeError, ValueError):
        return []
    if not isinstance(record, dict) or not isinstance(record.get("actions"), list):
        return []
    event = printable(str(record.get("event", "")), 120)
    out = []
    for item in record["actions"]:
        if not isinstance(item, dict) or item.get("ok", True):
            continue
        component = printable(str(item.get("component") or ""), 120)
        text = f"event {event}: action {printable(str(item.get('action', '')), 120)} {printable(str(item.get('detail', 'failed')), 200)}"
        out.append(Observation(component, "event", text, trouble=True))
    return out


class RecoveryBudget:
    """At most ``max_recoveries`` recovery tasks per component within ``window`` seconds."""

    def __init__(self, max_recoveries: int, window: float) -> None:
        self.max_recoveries, self.window = max_recoveries, window
        self._spent: dict[str, collections.deque[float]] = {}

    def allow(self, component: str, now: float) -> bool:
        spent = self._spent.setdefault(component, collections.deque())
        while spent and now - spent[0] > self.window:
            spent.popleft()
        if len(spent) >= self.max_recoveries:
            return False
        spent.append(now)
        return True


def recovery_task(component: str, observations: list[Observation]) -> str:
    """The task Cortex plans when ``component`` is in trouble (its first line names it, so a
    model, or a script, can tell recoveries from a user's tasks)."""
    lines = [f"RECOVER component '{component}': the system reports a problem."]
    lines += [f"- {o.text}" for o in observations[-8:]]
    lines.append("Use the tools to bring it back (restart_component, or one of its actions); answer DONE if nothing needs doing.")
    return "\n".join(lines)
