"""The ROS original's event classes: ``OnGreater("rviz_goal", topic, 0, ["header", "stamp", "sec"])``.

Each is an :class:`~emos.events.event.Event` whose condition is built from the topic, the path
of nested attributes and the trigger value, exactly as ``topic.msg.header.stamp.sec > 0`` would
be: an unknown attribute or a trigger value of the wrong kind fails here, at definition, naming
the topic, the field and the message type. Their firing is the original's:

* ``OnGreater`` / ``OnLess``: on every message whose value is above / below ``trigger_value``
  (``or_equal=True``: at or above / at or below). Level, not edge: a clicked point with
  ``header.stamp.sec > 0`` fires on every click. ``on_change=True`` (an EMOS option) fires only
  when the value crosses the threshold, and ``keep_event_delay`` / ``handle_once`` debounce;
* ``OnEqual`` / ``OnDifferent``: on every message whose value equals / differs from it;
* ``OnContainsAny`` / ``OnContainsAll``: the value (a list or a str) holds any / all of the
  trigger values (one value is a list of one);
* ``OnAny``: on every message of the topic.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from emos.events.conditions import Condition, ConditionError, MsgPath
from emos.events.event import Event
from emos.io.topic import Topic

__all__ = ["OnAny", "OnContainsAll", "OnContainsAny", "OnDifferent", "OnEqual", "OnGreater", "OnLess"]


def _source(cls_name: str, event_name: Any, event_source: Any) -> Topic:
    if not isinstance(event_name, str) or not event_name:
        raise ValueError(f"{cls_name}: event_name must be a non-empty str, got {event_name!r}")
    if not isinstance(event_source, Topic):
        raise TypeError(f"{cls_name}({event_name!r}): event_source must be a Topic "
                        f"(Topic(name=..., msg_type=...)), got {type(event_source).__name__} {event_source!r}")
    return event_source


def _path(cls_name: str, event_name: str, topic: Topic, nested_attributes: Any) -> MsgPath:
    """``topic.msg.<a>.<b>...``: each step is checked against the message type as it is taken."""
    if isinstance(nested_attributes, str):
        nested_attributes = [nested_attributes]
    if not isinstance(nested_attributes, Sequence) or not nested_attributes or not all(
            isinstance(a, str) and a for a in nested_attributes):
        raise ConditionError(f"{cls_name}({event_name!r}): nested_attributes must be a field name or a non-empty list of "
                             f"field names into the {topic.type_name} message (e.g. ['header', 'stamp', 'sec']), "
                             f"got {nested_attributes!r}")
    path: MsgPath = topic.msg
    for name in nested_attributes:
        path = getattr(path, name)
    return path


@contextmanager
def _named(cls_name: str, event_name: str) -> Iterator[None]:
    """Prefix a condition error with the event it is about (the field path says the rest)."""
    try:
        yield
    except ConditionError as exc:
        text = str(exc)
        if not text.startswith(f"{cls_name}("):
            raise ConditionError(f"{cls_name}({event_name!r}): {text}") from None
        raise


class _NamedEvent(Event):
    """An :class:`Event` built from (name, topic, trigger value, nested attributes)."""

    def __init__(self, event_name: str, condition: Condition | Topic, *, on_change: bool = False, handle_once: bool = False,
                 keep_event_delay: float = 0.0) -> None:
        super().__init__(condition, on_change=on_change, handle_once=handle_once, keep_event_delay=keep_event_delay, name=event_name)

    @property
    def event_name(self) -> str:
        return str(self.name)


class _Compare(_NamedEvent):
    _op = ""
    _op_or_equal = ""

    def __init__(self, event_name: str, event_source: Topic, trigger_value: Any, nested_attributes: str | Sequence[str],
                 or_equal: bool = False, *, on_change: bool = False, handle_once: bool = False, keep_event_delay: float = 0.0) -> None:
        cls_name = type(self).__name__
        topic = _source(cls_name, event_name, event_source)
        if not isinstance(or_equal, bool):
            raise TypeError(f"{cls_name}({event_name!r}): or_equal must be a bool, got {or_equal!r}")
        op = self._op_or_equal if or_equal else self._op
        with _named(cls_name, event_name):
            path = _path(cls_name, event_name, topic, nested_attributes)
            # The comparison operators of MsgPath check the trigger value against the field's type.
            condition = {"<": path.__lt__, "<=": path.__le__, ">": path.__gt__, ">=": path.__ge__,
                         "==": path.__eq__, "!=": path.__ne__}[op](trigger_value)
        self.trigger_value = trigger_value
        self.or_equal = or_equal
        super().__init__(event_name, condition, on_change=on_change, handle_once=handle_once, keep_event_delay=keep_event_delay)


class OnGreater(_Compare):
    """Fires on each message of ``event_source`` whose ``nested_attributes`` value is greater than
    ``trigger_value`` (``or_equal``: or equal to it)."""

    _op, _op_or_equal = ">", ">="


class OnLess(_Compare):
    """Fires on each message whose value is less than ``trigger_value`` (``or_equal``: or equal)."""

    _op, _op_or_equal = "<", "<="


class OnEqual(_Compare):
    """Fires on each message whose value equals ``trigger_value``."""

    _op = _op_or_equal = "=="

    def __init__(self, event_name: str, event_source: Topic, trigger_value: Any, nested_attributes: str | Sequence[str], *,
                 on_change: bool = False, handle_once: bool = False, keep_event_delay: float = 0.0) -> None:
        super().__init__(event_name, event_source, trigger_value, nested_attributes, on_change=on_change, handle_once=handle_once,
                         keep_event_delay=keep_event_delay)


class OnDifferent(_Compare):
    """Fires on each message whose value differs from ``trigger_value``."""

    _op = _op_or_equal = "!="

    def __init__(self, event_name: str, event_source: Topic, trigger_value: Any, nested_attributes: str | Sequence[str], *,
                 on_change: bool = False, handle_once: bool = False, keep_event_delay: float = 0.0) -> None:
        super().__init__(event_name, event_source, trigger_value, nested_attributes, on_change=on_change, handle_once=handle_once,
                         keep_event_delay=keep_event_delay)


class _Contains(_NamedEvent):
    _method = ""

    def __init__(self, event_name: str, event_source: Topic, trigger_value: Any, nested_attributes: str | Sequence[str], *,
                 on_change: bool = False, handle_once: bool = False, keep_event_delay: float = 0.0) -> None:
        cls_name = type(self).__name__
        topic = _source(cls_name, event_name, event_source)
        values = list(trigger_value) if isinstance(trigger_value, (list, tuple, set, frozenset)) else [trigger_value]
        with _named(cls_name, event_name):
            path = _path(cls_name, event_name, topic, nested_attributes)
            condition = getattr(path, self._method)(values)
        self.trigger_value = trigger_value
        super().__init__(event_name, condition, on_change=on_change, handle_once=handle_once, keep_event_delay=keep_event_delay)


class OnContainsAny(_Contains):
    """Fires on each message whose value (a list or a str) contains any of ``trigger_value``."""

    _method = "contains_any"


class OnContainsAll(_Contains):
    """Fires on each message whose value (a list or a str) contains all of ``trigger_value``."""

    _method = "contains_all"


class OnAny(_NamedEvent):
    """Fires on every message of ``event_source``."""

    def __init__(self, event_name: str, event_source: Topic, *, on_change: bool = False, handle_once: bool = False,
                 keep_event_delay: float = 0.0) -> None:
        topic = _source(type(self).__name__, event_name, event_source)
        super().__init__(event_name, topic, on_change=on_change, handle_once=handle_once, keep_event_delay=keep_event_delay)
