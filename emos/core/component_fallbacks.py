"""``ComponentFallbacks``: a component's fallback handlers as one object (the ROS original's class).

    from emos.core import ComponentFallbacks, BaseComponent
    from emos.core.fallbacks import Fallback

    fallbacks = ComponentFallbacks(
        on_algorithm_fail=Fallback([Action(method=planner.restart)], max_retries=2),
        on_any_fail=Action(method=planner.restart),
    )
    fallbacks.apply(planner)                    # same as planner.on_algorithm_fail(...), planner.on_fail(...)
    ComponentFallbacks.of(planner)              # the handlers a component has

It holds definitions only: the fallbacks run in the supervisor (:mod:`emos.core.fallbacks` holds
their state machine: ladders, ``max_retries``, give-up, budgets that reset once healthy again),
so every handler is checked here, at definition, with the same errors as ``component.on_*_fail``.
The original's ``on_any_fail`` is EMOS's ``on_fail``.
"""
from __future__ import annotations

from typing import Any

from emos.core.fallbacks import Fallback

__all__ = ["ComponentFallbacks"]

# constructor argument -> the component's handler key (and its on_* method)
_KEYS = {
    "on_any_fail": "on_fail",
    "on_component_fail": "on_component_fail",
    "on_algorithm_fail": "on_algorithm_fail",
    "on_system_fail": "on_system_fail",
    "on_giveup": "on_giveup",
}


def _fallback(arg: str, value: Any) -> Fallback | None:
    """A Fallback from a Fallback, an Action or a list of Actions (a ladder); None stays None."""
    if value is None or isinstance(value, Fallback):
        return value
    return Fallback(value, None, where=f"ComponentFallbacks({arg}=...)")


class ComponentFallbacks:
    """The handlers of one component: ``on_any_fail`` (any failure without its own handler),
    ``on_component_fail``, ``on_algorithm_fail``, ``on_system_fail`` and ``on_giveup`` (run
    once when a ladder is spent). Each is a :class:`~emos.core.fallbacks.Fallback`, an Action,
    a list of Actions (a ladder, each step tried once), or None."""

    def __init__(self, on_any_fail: Any = None, on_component_fail: Any = None, on_algorithm_fail: Any = None,
                 on_system_fail: Any = None, on_giveup: Any = None) -> None:
        self.on_any_fail = _fallback("on_any_fail", on_any_fail)
        self.on_component_fail = _fallback("on_component_fail", on_component_fail)
        self.on_algorithm_fail = _fallback("on_algorithm_fail", on_algorithm_fail)
        self.on_system_fail = _fallback("on_system_fail", on_system_fail)
        self.on_giveup = _fallback("on_giveup", on_giveup)

    def handlers(self) -> dict[str, Fallback]:
        """The handlers that are set, by the component's key (``on_fail``, ``on_system_fail``...)."""
        out = {}
        for arg, key in _KEYS.items():
            value = getattr(self, arg)
            if value is not None:
                out[key] = value
        return out

    def apply(self, component: Any) -> None:
        """Set these handlers on ``component`` (those left None keep what the component has)."""
        if not getattr(component, "_emos_component", False):
            raise TypeError(f"ComponentFallbacks.apply: expects a component (a BaseComponent), got {type(component).__name__} {component!r}")
        for key, fb in self.handlers().items():
            getattr(component, key)(fb.steps if fb.is_ladder else fb.steps[0], fb.max_retries)

    @classmethod
    def of(cls, component: Any) -> ComponentFallbacks:
        """The handlers ``component`` has now."""
        if not getattr(component, "_emos_component", False):
            raise TypeError(f"ComponentFallbacks.of: expects a component (a BaseComponent), got {type(component).__name__} {component!r}")
        have = component.fallbacks
        return cls(**{arg: have.get(key) for arg, key in _KEYS.items()})

    def __repr__(self) -> str:
        inner = ", ".join(f"{arg}={getattr(self, arg)!r}" for arg in _KEYS if getattr(self, arg) is not None)
        return f"ComponentFallbacks({inner})"
