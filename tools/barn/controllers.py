"""Navigators the BARN harness can drive with (``--controller NAME``); all of them live in
``emos.actors.nav.navigator``: the simulator only simulates."""
from __future__ import annotations

from collections.abc import Callable

from emos.actors.nav.navigator import Navigator


def _builtin() -> Navigator:
    from emos.actors.nav.navigator import GridNavigator

    return GridNavigator()


def _navcore(name: str) -> Callable[[], Navigator]:
    def factory() -> Navigator:
        from emos.actors.nav.navigator import NavCoreNavigator

        return NavCoreNavigator(name)

    return factory


# name -> (factory, one-line description). Factories import lazily.
def _builtin_carve() -> Navigator:
    from emos.actors.nav.navigator import GridNavigator

    nav = GridNavigator(carve_range=4.0, localize=False)
    nav.name = "builtin-carve"
    return nav


def _builtin_odom() -> Navigator:
    from emos.actors.nav.navigator import GridNavigator

    nav = GridNavigator(localize=False)
    nav.name = "builtin-odom"
    return nav


def _builtin_robust() -> Navigator:
    from emos.actors.nav.controllers.response import ResponseConfig
    from emos.actors.nav.navigator import GridNavigator

    nav = GridNavigator(response=ResponseConfig())
    nav.name = "builtin-robust"
    return nav


def _builtin_dynamic() -> Navigator:
    from emos.actors.nav.controllers.response import ResponseConfig
    from emos.actors.nav.navigator import DynamicGridNavigator

    return DynamicGridNavigator(response=ResponseConfig())


CONTROLLERS: dict[str, tuple[Callable[[], Navigator], str]] = {
    "builtin-robust": (_builtin_robust, "builtin planning with the arcs the base achieves (estimated yaw gain, lag, "
                                        "traction, speed-dependent margin)"),
    "builtin-dynamic": (_builtin_dynamic, "builtin-robust for moving obstacles: memory with evidence decay, tracked "
                                          "movers, arcs checked against their predicted positions"),
    "builtin": (_builtin, "scan-matched lidar obstacle memory + Dijkstra cost-to-go + sampled-arc local planner"),
    "builtin-odom": (_builtin_odom, "builtin without scan matching: trusts odometry"),
    "builtin-carve": (_builtin_carve, "builtin-odom, clearing free space along beams instead"),
}
for _name, _cls in (("navcore-dwa", "DWA"), ("navcore-purepursuit", "PurePursuit"),
                    ("navcore-stanley", "Stanley"), ("navcore-dvz", "DVZ"), ("mppi", "MPPI"),
                    ("rpp", "RegulatedPurePursuit")):
    CONTROLLERS[_name] = (_navcore(_name), f"simulator global plan + emos.actors.nav {_cls} local controller")


def make_controller(name: str) -> Navigator:
    try:
        factory, _ = CONTROLLERS[name]
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; choose from {sorted(CONTROLLERS)}") from None
    return factory()
