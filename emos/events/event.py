"""``Event``: when a condition over topics becomes true; and the state that decides firing.

    low_battery = Event(battery.msg.data < 20.0, on_change=True)
    any_command = Event(command_topic)                # fires on every message of the topic

The :class:`Event` is a definition (plain data once compiled, see :meth:`Event.to_dict`); the
:class:`EventTracker` holds what firing depends on at run time (the last value for
``on_change``, the last firing for ``keep_event_delay``, whether a ``handle_once`` event has
fired) and the :class:`Blackboard` the latest message of each topic, honouring ``data_timeout``.
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import attrs
import numpy as np

from emos.events.conditions import Condition, ConditionError, as_condition, compile_condition, render, topics_of
from emos.io.topic import Topic


class Event:
    """A condition over one or more topics, and how often it may fire.

    ``on_change``: fire only when the condition goes from not-true to true (for a bare Topic:
    when the message content differs from the previous one). ``handle_once``: fire at most once
    in the life of the system (restarts of the Monitor included). ``keep_event_delay``: seconds
    after a firing during which the event does not fire again (debounce).
    """

    _is_emos_event = True

    def __init__(
        self,
        event_condition: Condition | Topic,
        on_change: bool = False,
        handle_once: bool = False,
        keep_event_delay: float = 0.0,
        name: str | None = None,
    ) -> None:
        for flag, value in (("on_change", on_change), ("handle_once", handle_once)):
            if not isinstance(value, bool):
                raise TypeError(f"Event: {flag} must be a bool, got {value!r}")
        if isinstance(keep_event_delay, bool) or not isinstance(keep_event_delay, (int, float)) or not keep_event_delay >= 0:
            raise ValueError(f"Event: keep_event_delay must be a number of seconds >= 0, got {keep_event_delay!r}")
        if name is not None and (not isinstance(name, str) or not name):
            raise ValueError(f"Event: name must be a non-empty str, got {name!r}")
        self.whole_topic = isinstance(event_condition, Topic)
        try:
            self.condition: Condition = as_condition(event_condition, "Event")
        except ConditionError as exc:
            raise ConditionError(f"Event: event_condition must be a condition (topic.msg.<field> ...) or a Topic; {exc}") from None
        self.on_change = on_change
        self.handle_once = handle_once
        self.keep_event_delay = float(keep_event_delay)
        self.name = name

    @property
    def topics(self) -> dict[str, Topic]:
        return self.condition.topics

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "condition": self.condition.to_dict(), "whole_topic": self.whole_topic,
            "on_change": self.on_change, "handle_once": self.handle_once, "keep_event_delay": self.keep_event_delay,
        }

    def __repr__(self) -> str:
        label = f"{self.name!r}, " if self.name else ""
        return f"Event({label}{render(self.condition.tree)})"


class Blackboard:
    """The latest message of each topic, with the monotonic time it arrived."""

    def __init__(self, timeouts: Mapping[str, float]):
        self.timeouts = dict(timeouts)
        self._latest: dict[str, tuple[Any, float]] = {}

    def put(self, topic: str, msg: Any, at: float | None = None) -> None:
        self._latest[topic] = (msg, time.monotonic() if at is None else at)

    def latest(self, topic: str) -> Any | None:
        """The latest message whatever its age (for action bindings)."""
        item = self._latest.get(topic)
        return None if item is None else item[0]

    def fresh(self, topic: str, now: float | None = None) -> Any | None:
        """The latest message if it is younger than the topic's ``data_timeout`` (0 = never stale)."""
        item = self._latest.get(topic)
        if item is None:
            return None
        timeout = self.timeouts.get(topic, 0.0)
        if timeout and (time.monotonic() if now is None else now) - item[1] > timeout:
            return None
        return item[0]


def message_content(msg: Any) -> Any:
    """A comparable view of a message without its header (its stamp changes every message)."""
    if not attrs.has(type(msg)):
        return msg.tolist() if isinstance(msg, np.ndarray) else msg
    return tuple((f.name, message_content(getattr(msg, f.name))) for f in attrs.fields(type(msg)) if f.name != "header")


class EventTracker:
    """Decides, message by message, whether one event fires."""

    def __init__(self, spec: Mapping[str, Any], fired_before: bool = False):
        self.spec = spec
        self.tree = spec["condition"]["tree"]
        self._evaluate = compile_condition(self.tree)
        self.topics = topics_of(self.tree)
        self._whole_topic, self._on_change = bool(spec["whole_topic"]), bool(spec["on_change"])
        self.fired_once = fired_before
        self.last_value = False
        self.last_content: Any = None
        self.last_fire = -float("inf")
        self.fire_count = 0

    def check(self, trigger_topic: str, board: Blackboard, now: float | None = None, fresh: Any = None) -> bool:
        """``fresh``: optional ``topic -> fresh message or None`` computed once per message for
        all events (the Monitor's fast path); by default read from ``board`` at ``now``."""
        now = time.monotonic() if now is None else now
        if self._whole_topic:
            if trigger_topic not in self.topics:
                return False
            value: bool | None = True
            if self._on_change:
                content = message_content(board.latest(trigger_topic))
                value = content != self.last_content
                self.last_content = content
                return self._decide(bool(value), now)
        else:
            value = self._evaluate(fresh or (lambda t: board.fresh(t, now)), trigger_topic)
        return self.observe(value, now)

    @property
    def whole_topic(self) -> bool:
        """Fires on every message of its topic (``Event(topic)``): no condition to evaluate."""
        return self._whole_topic

    @property
    def on_change(self) -> bool:
        return self._on_change

    def observe(self, value: bool | None, now: float) -> bool:
        """Whether the event fires, given its condition's ``value`` on this message (True, False
        or None: unknown). :meth:`check` evaluates and observes; the Monitor evaluates all the
        conditions of a topic in one call and observes the ones that matter."""
        truth = value is True
        if not self._on_change:
            return truth and self._decide(True, now)  # most events are false on most messages
        # on_change: an edge is false -> true over *known* values. Unknown (an input missing or
        # stale) neither fires nor re-arms the edge: otherwise a Monitor descheduled for longer
        # than a data_timeout, reading one topic's backlog before another's, would see the
        # other as stale for one message and fire the same event a second time.
        if value is None:
            return False
        rising = truth and not self.last_value
        self.last_value = truth
        return self._decide(rising, now)

    def _decide(self, fire: bool, now: float) -> bool:
        if not fire or (self.spec["handle_once"] and self.fired_once):
            return False
        if now - self.last_fire < self.spec["keep_event_delay"]:
            return False
        self.last_fire = now
        self.fired_once = True
        self.fire_count += 1
        return True
