"""What a robot plugin declares: its feedback, commands, heartbeats, actions and events.

These are plain descriptions on the plugin class; :class:`~.component.RobotPlugin` turns them
into keyed topics (so a recipe rewires them as it rewires the Simulator's: ``base.outputs(odom=
...)``), into timers and into :class:`~emos.events.Event` objects, and ``emos robot inspect``
lists them without starting anything.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import attrs

from emos.config import validators as V

__all__ = ["Feedback", "Command", "Heartbeat", "PluginEvent", "plugin_action"]

F = TypeVar("F", bound=Callable[..., Any])


@attrs.frozen(kw_only=True)
class Feedback:
    """Device bytes -> messages on a topic: ``msg_type`` on ``topic`` (the default name)."""

    msg_type: str = attrs.field(validator=V.non_empty_str)
    topic: str = attrs.field(validator=V.non_empty_str)
    help: str = ""


def _type_names(value: Any) -> tuple[str, ...]:
    names = (value,) if isinstance(value, str) else tuple(value)
    if not names or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"Command.msg_types: expected one or more message type names, got {value!r}")
    return names


@attrs.frozen(kw_only=True)
class Command:
    """Messages on a topic -> device bytes. ``timeout``: the name of the plugin's config field
    holding the command watchdog period (no fresh message for that long: ``on_command_timeout``),
    or None for commands that may stay."""

    msg_types: tuple[str, ...] = attrs.field(converter=_type_names)
    topic: str = attrs.field(validator=V.non_empty_str)
    timeout: str | None = None
    help: str = ""


@attrs.frozen(kw_only=True)
class Heartbeat:
    """A keep-alive: ``payload`` written to transport ``transport`` every ``period`` s while it is
    up (devices that stop when their host goes quiet want one)."""

    transport: str = attrs.field(validator=V.non_empty_str)
    period: float = attrs.field(validator=V.finite_positive)
    payload: bytes = attrs.field(validator=attrs.validators.instance_of(bytes))
    help: str = ""


@attrs.frozen(kw_only=True)
class PluginEvent:
    """An event the plugin raises to the Monitor: a condition over one of its feedback topics,
    ``condition(topic) -> Condition`` (e.g. ``lambda t: t.msg.percentage < 0.15``), described in
    ``when`` for ``emos robot inspect``. Edge-triggered (``on_change``) unless said otherwise."""

    feedback: str = attrs.field(validator=V.non_empty_str)
    condition: Callable[[Any], Any]
    when: str = ""
    on_change: bool = True
    keep_event_delay: float = 0.0
    help: str = ""


def plugin_action(help: str) -> Callable[[F], F]:
    """Mark a public method of a plugin as a plugin action: it is listed by ``emos robot
    inspect``, and events (``Action(method=base.dock)``) and ``emos component call NAME
    execute_method method=dock`` call it inside the plugin's process, between two steps."""

    def mark(fn: F) -> F:
        if fn.__name__.startswith("_"):
            raise ValueError(f"plugin_action {fn.__name__!r}: actions are public methods (no leading '_')")
        fn._emos_plugin_action = help  # type: ignore[attr-defined]
        return fn

    return mark
