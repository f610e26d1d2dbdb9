"""The ROS 2 bridge as a Launcher frontend: entry point ``ros2`` in the group ``emos.frontends``
(emos/frontends.py). ``request`` checks the options where the recipe (or ``emos run --ros2``)
gives them; ``add`` puts the bridge in its own supervised group."""
from __future__ import annotations

from typing import Any

from emos.actors.ros2.component import Ros2BridgeComponent, Ros2BridgeConfig, config_from_environment


def request(**options: Any) -> Ros2BridgeConfig:
    from emos.interop.ros2 import env

    env.require()
    return Ros2BridgeConfig(**options) if options else config_from_environment()


def add(launcher: Any, request: Ros2BridgeConfig) -> None:
    bridge = Ros2BridgeComponent(config=request)
    launcher.add_pkg(components=[bridge], package_name="ros2", multiprocessing=True)
