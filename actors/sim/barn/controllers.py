"""Controllers the BARN harness can drive with (``--controller NAME``)."""
from __future__ import annotations

from typing import Callable

from ..navigation.interface import Navigator


def _builtin() -> Navigator:
    from ..navigation.builtin import GridNavigator

    return GridNavigator()


# name -> (factory, one-line description). Factories import lazily.
CONTROLLERS: dict[str, tuple[Callable[[], Navigator], str]] = {
    "builtin": (_builtin, "lidar obstacle memory + Dijkstra cost-to-go + sampled-arc local planner"),
}


def make_controller(name: str) -> Navigator:
    try:
        factory, _ = CONTROLLERS[name]
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; choose from {sorted(CONTROLLERS)}") from None
    return factory()
