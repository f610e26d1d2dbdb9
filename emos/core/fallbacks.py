"""Fallbacks: what to do, step by step, while a component reports a failure.

A recipe attaches them to a component (``planner.on_algorithm_fail(action=[...], max_retries=1)``)
or to the whole launcher (``launcher.on_fail(action_name="restart")``). They run in the
supervisor (``emos.supervisor.fallback_driver``), which watches every ``<name>/status`` stream:
a component's own process may be the thing being restarted, and the retry budget must survive
that. The pure state machine is here:

* handler choice: the handler of the reported level (``on_system_fail``, ``on_component_fail``,
  ``on_algorithm_fail``), else the component's ``on_fail``, else the launcher-wide policy of
  that level, else the launcher's ``on_fail``, else the default: a component that keeps
  reporting COMPONENT_FAILURE for :data:`DEFAULT_RESTART_AFTER_S` is restarted through the
  supervisor (so its restart intensity bounds it). ALGORITHM and SYSTEM failures have no default.
* a ladder (one action or a list) runs each step exactly ``max_retries`` times, then the next;
  ``None`` means unlimited for a single action and once per step for a list (a list that never
  moved past its first step would not be a ladder). When the ladder is spent the component gives
  up: ``on_giveup`` runs once and nothing else runs until it recovers.
* attempts are at most ``fallback_rate`` per second.
* budgets reset when the component has been HEALTHY again for ``reset_after`` seconds (not over
  the component's lifetime, as the original did).
"""
from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import Any

from emos.core.control import request_lifecycle
from emos.core.health import HealthLevel

DEFAULT_RESTART_AFTER_S = 0.25
DEFAULT_RESET_AFTER_S = 10.0

LEVEL_HANDLERS = {
    HealthLevel.SYSTEM_FAILURE: "on_system_fail",
    HealthLevel.COMPONENT_FAILURE: "on_component_fail",
    HealthLevel.ALGORITHM_FAILURE: "on_algorithm_fail",
}
HANDLERS = ("on_system_fail", "on_component_fail", "on_algorithm_fail", "on_fail")


class Fallback:
    """One handler: an action or a ladder of actions, and how often each step is tried."""

    def __init__(self, action: Any, max_retries: int | None = None, where: str = "fallback"):
        from emos.events.action import Action

        steps = list(action) if isinstance(action, (list, tuple)) else [action]
        if not steps:
            raise ValueError(f"{where}: the ladder is empty; give an Action or a list of Actions")
        for a in steps:
            if not isinstance(a, Action):
                raise TypeError(f"{where}: fallbacks are Actions (Action(...) or emos.actions.*), got {type(a).__name__} {a!r}")
        if max_retries is not None and (isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 1):
            raise ValueError(f"{where}: max_retries must be an int >= 1 or None (unlimited), got {max_retries!r}")
        self.steps = steps
        self.max_retries = max_retries
        self.is_ladder = isinstance(action, (list, tuple))

    @property
    def per_step(self) -> int | None:
        if self.max_retries is not None:
            return self.max_retries
        return 1 if self.is_ladder else None

    def __repr__(self) -> str:
        return f"Fallback({self.steps!r}, max_retries={self.max_retries})"


class Ladder:
    """Where one handler is: which step, how many tries of it."""

    def __init__(self, fallback: Fallback):
        self.fallback = fallback
        self.step = 0
        self.tries = 0

    def next(self) -> tuple[Any, int, int] | None:
        """(action, step index, try number from 1) or None when spent."""
        fb = self.fallback
        per_step = fb.per_step
        if self.step >= len(fb.steps):
            return None
        self.tries += 1
        out = (fb.steps[self.step], self.step, self.tries)
        if per_step is not None and self.tries >= per_step:
            self.step += 1
            self.tries = 0
        return out

    def reset(self) -> None:
        self.step = self.tries = 0


class FallbackTracker:
    """The fallback state of one component, fed with its status stream."""

    def __init__(self, handlers: dict[str, Fallback], giveup: Fallback | None, default: Fallback | None,
                 rate: float, reset_after: float = DEFAULT_RESET_AFTER_S, default_after: float = DEFAULT_RESTART_AFTER_S):
        if not rate > 0:
            raise ValueError(f"fallback_rate must be > 0 Hz, got {rate!r}")
        self.handlers = handlers
        self.giveup = giveup
        self.default = default
        self.period = 1.0 / rate
        self.reset_after = reset_after
        self.default_after = default_after
        self.ladders: dict[str, Ladder] = {}
        self.gave_up = False
        self.gave_up_on = ""
        self.level = HealthLevel.HEALTHY
        self.healthy_since: float | None = None
        self.failing_since: float | None = None
        self.last_attempt = -float("inf")
        self.attempts = 0

    def observe(self, level: int, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        try:
            level = HealthLevel(level)
        except ValueError:  # a level this version does not know
            level = HealthLevel.GENERAL
        if level in LEVEL_HANDLERS:
            self.healthy_since = None
            if self.failing_since is None or self.level not in LEVEL_HANDLERS:
                self.failing_since = now
        else:
            self.failing_since = None
            if self.healthy_since is None:
                self.healthy_since = now
            elif now - self.healthy_since >= self.reset_after and (self.ladders or self.gave_up):
                self.reset()
        self.level = level

    def reset(self) -> None:
        self.ladders.clear()
        self.gave_up = False
        self.gave_up_on = ""

    @property
    def failing(self) -> bool:
        return self.level in LEVEL_HANDLERS

    def handler_for(self, level: HealthLevel) -> tuple[str, Fallback] | None:
        specific = LEVEL_HANDLERS.get(level)
        for key in (specific, "on_fail"):
            if key and key in self.handlers:
                return key, self.handlers[key]
        if level == HealthLevel.COMPONENT_FAILURE and self.default is not None:
            return "default", self.default
        return None

    def wait_s(self, now: float | None = None) -> float:
        """Seconds until the next attempt is allowed (0: now)."""
        now = time.monotonic() if now is None else now
        wait = self.last_attempt + self.period - now
        if self.failing_since is not None and self.handler_for(self.level) is not None and self.handler_for(self.level)[0] == "default":  # type: ignore[index]
            wait = max(wait, self.failing_since + self.default_after - now)
        return max(0.0, wait)

    def next(self, now: float | None = None) -> dict[str, Any] | None:
        """The next thing to do for the current failure, or None (healthy, no handler, gave up,
        or too early). A dict: kind "action" (action, handler, step, try) or "giveup"."""
        now = time.monotonic() if now is None else now
        if not self.failing or self.gave_up or self.wait_s(now) > 0:
            return None
        found = self.handler_for(self.level)
        if found is None:
            return None
        key, fallback = found
        ladder = self.ladders.setdefault(key, Ladder(fallback))
        step = ladder.next()
        self.last_attempt = now
        if step is None:
            self.gave_up = True
            self.gave_up_on = key
            return {"kind": "giveup", "handler": key, "actions": list(self.giveup.steps) if self.giveup else []}
        self.attempts += 1
        action, index, attempt = step
        return {"kind": "action", "handler": key, "action": action, "step": index, "try": attempt,
                "of": fallback.per_step, "steps": len(fallback.steps)}


# ============================================================================ recipe API
def component_fallback(method: Callable[..., Any]) -> Callable[..., Any]:
    """Mark a component method as a fallback: it runs only while the component is configured
    (Inactive or Active) and returns True when it recovered the component."""

    @functools.wraps(method)
    def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
        state = getattr(self.lifecycle_state, "value", "")
        if state not in ("inactive", "active"):
            self.get_logger().warning("[%s] fallback %s skipped: component is %s", self.component_name, method.__name__, state or "not running")
            return False
        return bool(method(self, *args, **kwargs))

    wrapper._emos_component_fallback = True  # type: ignore[attr-defined]
    return wrapper


def _fallback_arg(where: str, action: Any, fallback: Any) -> Any:
    if action is not None and fallback is not None:
        raise TypeError(f"{where}: give the action once (action= or fallback=), not both")
    value = action if action is not None else fallback
    if value is None:
        raise TypeError(f"{where}: missing the action (an Action or a list of Actions)")
    return value


def _lifecycle_request_method(method: Callable[..., Any]) -> Callable[..., Any]:
    """Mark ``start``/``stop``/``restart`` below: an Action of one of them (not of a subclass's
    override, which has no mark) is a lifecycle request (see emos.events.action)."""
    method._emos_lifecycle_request = True  # type: ignore[attr-defined]
    return method


class FallbackHooks:
    """The ``on_*_fail`` methods of :class:`~emos.core.component.BaseComponent`."""

    # Lets emos.events.action tell a component's method from any other callable without
    # importing the component module (which imports this one).
    _emos_component = True
    _fallbacks: dict[str, Fallback]
    component_name: str

    def _set_fallback(self, key: str, action: Any, max_retries: int | None, fallback: Any) -> None:
        where = f"{self.component_name}.{key}"
        if "_fallbacks" not in self.__dict__:
            self._fallbacks = {}
        self._fallbacks[key] = Fallback(_fallback_arg(where, action, fallback), max_retries, where)

    def on_fail(self, action: Any = None, max_retries: int | None = None, *, fallback: Any = None) -> None:
        """Catch-all: for any failure level without its own handler."""
        self._set_fallback("on_fail", action, max_retries, fallback)

    def on_system_fail(self, action: Any = None, max_retries: int | None = None, *, fallback: Any = None) -> None:
        """For SYSTEM_FAILURE (inputs missing or stale, dependencies down)."""
        self._set_fallback("on_system_fail", action, max_retries, fallback)

    def on_component_fail(self, action: Any = None, max_retries: int | None = None, *, fallback: Any = None) -> None:
        """For COMPONENT_FAILURE (the component itself is broken; steps that raise report it)."""
        self._set_fallback("on_component_fail", action, max_retries, fallback)

    def on_algorithm_fail(self, action: Any = None, max_retries: int | None = None, *, fallback: Any = None) -> None:
        """For ALGORITHM_FAILURE (the step ran but found no answer)."""
        self._set_fallback("on_algorithm_fail", action, max_retries, fallback)

    def on_giveup(self, action: Any = None, max_retries: int | None = None, *, fallback: Any = None) -> None:
        """Run once when a ladder is spent (every step tried ``max_retries`` times)."""
        self._set_fallback("on_giveup", action, max_retries, fallback)

    @property
    def fallbacks(self) -> dict[str, Fallback]:
        return dict(self.__dict__.get("_fallbacks", {}))

    # -- lifecycle requests (as actions they go through the supervisor; see emos.actions) -------
    @_lifecycle_request_method
    def start(self) -> None:
        """Ask the supervisor to activate this component."""
        self._lifecycle_request("start")

    @_lifecycle_request_method
    def stop(self) -> None:
        """Ask the supervisor to deactivate this component."""
        self._lifecycle_request("stop")

    @_lifecycle_request_method
    def restart(self, wait_time: float = 0.0) -> None:
        """Ask the supervisor to restart this component (counted against its restart intensity)."""
        self._lifecycle_request("restart", wait_time)

    def _lifecycle_request(self, op: str, wait_time: float = 0.0) -> None:
        node = getattr(self, "_node", None)
        if node is None:
            # BaseComponent.node raises its ComponentError while not running: the same error,
            # saying what a recipe does instead (no import of the component module from here).
            try:
                node = self.node  # type: ignore[attr-defined]
            except Exception as exc:
                raise type(exc)(f"component {self.component_name!r} is not running; use emos.actions.{op}(component=...) in a recipe") from None
        request_lifecycle(node, op, wait_time)

