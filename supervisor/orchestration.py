"""What a recipe asked the runtime to react to: events and actions, and fallback policies.

The ``Launcher`` collects these (``add_pkg(events_actions=...)``, ``launcher.on_fail(...)``,
components whose trigger is an Event) into an :class:`Orchestration`, checked when the recipe is
loaded; the ``System`` runs it: events in the Monitor (``monitor.py``), fallbacks in the
supervisor (``fallback_driver.py``).
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from attrs import define, field

from emos.core.component import BaseComponent
from emos.core.fallbacks import DEFAULT_RESET_AFTER_S, HANDLERS, LEVEL_HANDLERS, Fallback
from emos.events.action import Action, call_signature_error
from emos.events.event import Event
from emos.events.runner import step_action

LAUNCHER_POLICY_ACTIONS = ("restart", "stop", "start")


def normalize_events_actions(events_actions: Any, where: str = "add_pkg(events_actions=...)") -> list[tuple[Event, list[Action]]]:
    """``{event: action or [actions]}`` checked and as a list of pairs (in recipe order)."""
    if not isinstance(events_actions, dict):
        raise TypeError(f"{where}: expects a dict mapping Events to an Action or a list of Actions, got {type(events_actions).__name__}")
    out = []
    for event, actions in events_actions.items():
        if not isinstance(event, Event):
            raise TypeError(f"{where}: keys must be Events (Event(condition, ...)), got {type(event).__name__} {event!r}")
        steps = list(actions) if isinstance(actions, (list, tuple)) else [actions]
        if not steps:
            raise ValueError(f"{where}: {event!r} has no actions")
        for a in steps:
            if not isinstance(a, Action):
                raise TypeError(f"{where}: {event!r} maps to {type(a).__name__} {a!r}; expected an Action (Action(...) or emos.actions.*)")
        out.append((event, steps))
    return out


@define(kw_only=True)
class Orchestration:
    events_actions: list[tuple[Event, list[Action]]] = field(factory=list)
    policies: dict[str, tuple[str, int | None]] = field(factory=dict)  # launcher-wide: handler -> (action name, max_retries)
    fallback_rate: float | None = None  # launcher-wide override of every component's config.fallback_rate
    reset_after: float = DEFAULT_RESET_AFTER_S
    action_timeout: float = 10.0
    monitor_nice: int = 5
    monitor_defer_ms: float = 0.0
    report_outcomes: bool = False  # the Monitor publishes each event's outcome (a Cortex monitors the run)

    def all_events(self, components: Sequence[BaseComponent]) -> list[tuple[Event, list[Action]]]:
        """Recipe events, the events components bring along (a VLA's stop event), and one per
        component whose trigger is an Event (it runs a step)."""
        entries = list(self.events_actions)
        for c in components:
            entries.extend(getattr(c, "_own_events_actions", ()))
            event = getattr(c, "_event_trigger", None)
            if event is not None:
                entries.append((event, [step_action(c)]))
        return entries

    def check(self, components: Sequence[BaseComponent]) -> None:
        """Definition-time checks that need the whole system: targets exist, arguments bind."""
        names = {c.component_name for c in components}
        for event, actions in self.all_events(components):
            for a in actions:
                # The Monitor sends an event's action on a component of another run over Zenoh.
                _check_target(a, names, f"event {event!r}", remote_ok=True)
        for c in components:
            for key, fb in c.fallbacks.items():
                for a in fb.steps:
                    _check_target(a, names, f"{c.component_name}.{key}")
        for key, (action_name, _) in self.policies.items():
            for c in components:
                if action_name in LAUNCHER_POLICY_ACTIONS:
                    continue
                method = getattr(c, action_name, None)
                if action_name.startswith("_") or not callable(method):
                    raise ValueError(f"launcher.{key}(action_name={action_name!r}): component {c.component_name!r} has no public method {action_name!r}; "
                                     f"use one of {', '.join(LAUNCHER_POLICY_ACTIONS)} or a method every component has")

    def handlers_for(self, component: BaseComponent) -> dict[str, Fallback]:
        """The component's own handlers, completed by the launcher-wide policies: a level the
        component left open (and no own ``on_fail``) gets the launcher's policy for that level,
        else the launcher's ``on_fail``."""
        own = component.fallbacks
        handlers = {k: v for k, v in own.items() if k in HANDLERS}
        if "on_fail" in handlers:
            return handlers
        launcher = self.launcher_fallbacks(component)
        for key in LEVEL_HANDLERS.values():
            if key not in handlers and (key in launcher or "on_fail" in launcher):
                handlers[key] = launcher.get(key) or launcher["on_fail"]
        return handlers

    def launcher_fallbacks(self, component: BaseComponent) -> dict[str, Fallback]:
        """The launcher-wide policies as fallbacks of one component."""
        from emos import actions as A

        out = {}
        for key, (action_name, max_retries) in self.policies.items():
            if action_name in LAUNCHER_POLICY_ACTIONS:
                action = getattr(A, action_name)(component=component)
            else:
                action = Action(getattr(component, action_name))
            out[key] = Fallback(action, max_retries, f"launcher.{key}")
        return out


def _check_target(action: Action, names: set[str], where: str, remote_ok: bool = False) -> None:
    if action.component is not None and action.component not in names:
        from emos.supervisor.monitor_net import uses_zenoh

        if not (remote_ok and uses_zenoh()):
            hint = ("; a component of another run can be the target of an event's action when this run uses Zenoh (emos run --zenoh CONFIG)"
                    if remote_ok else "; fallbacks act on components of their own run only")
            raise ValueError(f"{where}: action {action.describe()} targets component {action.component!r}, which is not in this launcher "
                             f"(components: {', '.join(sorted(names))}){hint}")
        logging.getLogger("emos.monitor").info("%s: action %s targets component %r, not in this run: the Monitor sends it over Zenoh "
                                               "to the run of the group that has it", where, action.describe(), action.component)
    if action.kind in ("component", "function"):
        error = call_signature_error(action.method, action.args, action.kwargs) if not action.parsers else None
        if error:
            raise TypeError(f"{where}: action {action.describe()} cannot be called with args={action.args!r} kwargs={action.kwargs!r}: {error}")


def check_policy(key: str, action_name: Any, max_retries: Any) -> tuple[str, int | None]:
    if key not in HANDLERS:
        raise ValueError(f"unknown fallback policy {key!r}")
    if not isinstance(action_name, str) or not action_name:
        raise TypeError(f"launcher.{key}: action_name must be the name of a component action such as 'restart', got {action_name!r}")
    if max_retries is not None and (isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 1):
        raise ValueError(f"launcher.{key}: max_retries must be an int >= 1 or None, got {max_retries!r}")
    return action_name, max_retries


def with_monitor(packages: list[Any], orchestration: Orchestration) -> list[Any]:
    """The packages plus, when the recipe has events, one group holding the Monitor (first)."""
    from emos.supervisor.monitor import Monitor
    from emos.supervisor.system import Package, SupervisionPolicy

    components = [c for p in packages for c in p.components]
    orchestration.check(components)
    entries = orchestration.all_events(components)
    if not entries:
        return list(packages)
    monitor = Monitor(entries, orchestration.action_timeout, nice=orchestration.monitor_nice, defer_ms=orchestration.monitor_defer_ms,
                      local_components=[c.component_name for c in components], report_outcomes=orchestration.report_outcomes)
    if monitor.component_name in {c.component_name for c in components}:
        raise ValueError(f"component name {monitor.component_name!r} is reserved for the Monitor")
    multiprocessing = any(p.multiprocessing for p in packages)
    # First, so the events are armed before any component publishes (and it stops last).
    return [Package(components=[monitor], multiprocessing=multiprocessing, activate=True,
                    policy=SupervisionPolicy(max_restarts=10, max_seconds=10.0), name="monitor")] + list(packages)


def requester(value: Any) -> str:
    """Who asked for a lifecycle operation (a request's optional ``by``: ``cli``, ``ui``, ``event``,
    ``component``...): a short word, or "" when absent or not a plain name (it lands in logs and
    in ``emos status``, so a peer's bytes are not echoed)."""
    if isinstance(value, str) and 0 < len(value) <= 32 and all(ch.isalnum() or ch in "-_." for ch in value):
        return value
    return ""


def lifecycle_op(driver: Callable[[], Any]) -> Any:
    """The supervisor socket's ``lifecycle`` operation: start / stop / restart a component.

    A restart asked here is counted as ``requested`` (by ``req["by"]`` if given), never as a crash."""
    import asyncio
    import logging

    from emos.supervisor.tree import REQUESTED

    # Operations run without waiting (``wait: false``) are held here until done: the event loop
    # keeps only weak references to tasks.
    background_tasks: set[asyncio.Future[None]] = set()

    async def lifecycle(req: dict, stream: Any) -> Any:
        coro = driver().lifecycle(str(req.get("component", "")), str(req.get("request", "")), float(req.get("wait_time") or 0.0),
                                  why=REQUESTED, by=requester(req.get("by")))
        if req.get("wait", True):
            return await coro

        async def background() -> None:
            try:
                await coro
            except Exception as exc:
                logging.getLogger("emos.supervisor").error("lifecycle %s of %s failed: %s", req.get("request"), req.get("component"), exc)

        task = asyncio.ensure_future(background())
        background_tasks.add(task)
        task.add_done_callback(background_tasks.discard)
        return True

    return lifecycle


def fallback_summary(events: Any, components: Sequence[BaseComponent]) -> list[str]:
    """Summary lines: fallback attempts and give-ups per component."""
    import collections

    attempts: collections.Counter[str] = collections.Counter()
    gave_up: set[str] = set()
    for e in events:
        if e.get("event") == "fallback":
            attempts[e["child"]] += 1
        elif e.get("event") == "gave_up":
            gave_up.add(e["child"])
    parts = [f"{c.component_name} {attempts[c.component_name]}" for c in components if attempts[c.component_name]]
    lines = [f"  fallback actions run: {', '.join(parts)}"] if parts else []
    if gave_up:
        lines.append(f"  gave up (fallbacks exhausted): {', '.join(sorted(gave_up))}")
    return lines
