"""``Action``: something to run when an event fires or a fallback steps, with live arguments.

    Action(method=driver.move_to_unblock)                       # runs inside the driver's process
    Action(method=navigate_to, args=(command_topic.msg.data,))  # a recipe function, in the Monitor
    restart(component=planner)                                  # predefined (emos.actions)

Where an action runs is decided here, once, from its target:

* a method of a component (``component.method``): inside that component's process, on its
  event loop, between two steps (never concurrently with one). ``start``/``stop``/``restart``
  of :class:`BaseComponent` are lifecycle requests and go through the supervisor instead;
* any other callable (a recipe function): in the Monitor (events) or the supervisor (fallbacks),
  in a worker thread so a slow function never stalls event evaluation;
* a predefined action of :mod:`emos.actions`: where that action says.

Any argument may be a binding: ``topic.msg.<field>`` (the field's value) or the Topic itself
(the whole message), resolved from the latest message of that topic at the moment the action
runs (dynamic data injection); a topic with no message yet gives None.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from typing import Any

# The wire format of arguments (and ActionError) live with the rest of the control plane; they
# are re-exported here, where recipes and older code import them from.
from emos.core.control import LIFECYCLE_REQUESTS, ActionError, decode_value, encode_value, is_public_name
from emos.events.conditions import _MISSING, MsgPath, resolve_path
from emos.io.topic import Topic

LIFECYCLE_METHODS = LIFECYCLE_REQUESTS

__all__ = ["Action", "ActionError", "Literal", "LIFECYCLE_METHODS", "resolve_bindings", "call_signature_error",
           "encode_value", "decode_value"]


class Action:
    def __init__(self, method: Callable[..., Any], args: Any = (), kwargs: dict[str, Any] | None = None) -> None:
        if not callable(method):
            raise TypeError(f"Action: method must be callable (a component method, a function or a predefined action), got {type(method).__name__} {method!r}")
        if not isinstance(args, (tuple, list)):
            args = (args,)  # Action(f, args=(x)) is a common slip for args=(x,)
        if kwargs is None:
            kwargs = {}
        if not isinstance(kwargs, dict) or not all(isinstance(k, str) for k in kwargs):
            raise TypeError(f"Action: kwargs must be a dict with str keys, got {kwargs!r}")
        self.method = method
        self.args: tuple[Any, ...] = tuple(args)
        self.kwargs: dict[str, Any] = dict(kwargs)
        self.parsers: list[tuple[Callable[..., Any], str | None]] = []
        self.kind = "function"
        self.component: str | None = None
        self.method_name = getattr(method, "__name__", type(method).__name__)
        self.predefined: str | None = None
        self._classify()

    def _classify(self) -> None:
        owner = getattr(self.method, "__self__", None)
        component = getattr(owner, "component_name", None)
        # A component (BaseComponent, through emos.core.fallbacks.FallbackHooks) says so with a
        # class attribute: this module is imported by the component's, so it does not import it.
        if getattr(owner, "_emos_component", False) is True and isinstance(component, str):
            self.component = component
            name = self.method.__name__
            # BaseComponent's own start/stop/restart are lifecycle requests (they carry a mark);
            # a subclass that overrides one (a DriveManager's stop = brake) is an ordinary
            # component method.
            if name in LIFECYCLE_METHODS and getattr(self.method, "_emos_lifecycle_request", False) is True:
                self.kind = "lifecycle"
                if self.args or set(self.kwargs) - {"wait_time"}:
                    raise TypeError(f"Action: {self.component}.{name} takes only wait_time; got args={self.args!r} kwargs={self.kwargs!r}")
                self.kwargs = {"component": self.component, "op": name, **self.kwargs}
            else:
                self.kind = "component"
                if not is_public_name(name):
                    # A component runs only its public methods for others (emos.core.control).
                    raise ValueError(f"Action: {self.component}.{name} is not a method an action may call (only public methods: no leading '_')")

    @classmethod
    def _predefined(cls, name: str, impl: Callable[..., Any], target: str | None = None, **kwargs: Any) -> Action:
        action = cls(impl, kwargs=kwargs)
        action.kind = "predefined"
        action.predefined = name
        action.component = target
        return action

    def event_parser(self, method: Callable[..., Any], output_mapping: str | None = None) -> Action:
        """Run ``method(msg=<the event's message>)`` when the action fires and pass its result as
        the keyword argument ``output_mapping`` (or as the first positional argument)."""
        if not callable(method):
            raise TypeError(f"Action.event_parser: method must be callable, got {method!r}")
        if output_mapping is not None and not isinstance(output_mapping, str):
            raise TypeError(f"Action.event_parser: output_mapping must be a keyword name, got {output_mapping!r}")
        self.parsers.append((method, output_mapping))
        return self

    @property
    def bound_topics(self) -> dict[str, Topic]:
        """Topics whose latest message the arguments need."""
        out: dict[str, Topic] = {}
        for value in _walk(list(self.args) + list(self.kwargs.values())):
            if isinstance(value, MsgPath):
                out[value._topic.name] = value._topic
            elif isinstance(value, Topic):
                out[value.name] = value
        return out

    def describe(self) -> str:
        if self.kind == "predefined":
            shown = ", ".join(f"{k}={v!r}" for k, v in self.kwargs.items() if k not in ("component", "key") and v is not None)
            return f"{self.predefined}({shown})"
        if self.kind == "lifecycle":
            return f"{self.kwargs['op']}({self.component})"
        if self.component:
            return f"{self.component}.{self.method_name}()"
        return f"{getattr(self.method, '__module__', '?')}.{getattr(self.method, '__qualname__', self.method_name)}()"

    def __repr__(self) -> str:
        return f"Action({self.describe()})"


def _walk(values: Iterable[Any]) -> Iterable[Any]:
    for v in values:
        if isinstance(v, (list, tuple)):
            yield from _walk(v)
        elif isinstance(v, dict):
            yield from _walk(v.values())
        else:
            yield v


class Literal:
    """An argument that is used as it is, never resolved as a binding (e.g. the Topic an action
    publishes on)."""

    __slots__ = ("value",)

    def __init__(self, value: Any):
        self.value = value

    def __repr__(self) -> str:
        return repr(self.value)


def resolve_bindings(value: Any, latest: Callable[[str], Any]) -> Any:
    """Replace topic bindings by the latest data (None when the topic has no message yet)."""
    if isinstance(value, Literal):
        return value.value
    if isinstance(value, MsgPath):
        msg = latest(value._topic.name)
        if msg is None:
            return None
        out = resolve_path(value.to_dict(), msg)
        return None if out is _MISSING else out
    if isinstance(value, Topic):
        return latest(value.name)
    if isinstance(value, tuple):
        return tuple(resolve_bindings(v, latest) for v in value)
    if isinstance(value, list):
        return [resolve_bindings(v, latest) for v in value]
    if isinstance(value, dict):
        return {k: resolve_bindings(v, latest) for k, v in value.items()}
    return value


def call_signature_error(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> str | None:
    """Why ``fn(*args, **kwargs)`` cannot bind, or None (checked when the recipe is loaded)."""
    try:
        inspect.signature(fn).bind(*args, **kwargs)
    except TypeError as exc:
        return str(exc)
    except ValueError:
        return None  # builtins without a signature
    return None
