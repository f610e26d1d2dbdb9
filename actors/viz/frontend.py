"""The Foxglove live view as a Launcher frontend: entry point ``foxglove`` in the group
``emos.frontends`` (see emos/frontends.py). ``Launcher.enable_foxglove`` calls ``request`` and
then ``add`` at once: the bridge is its own supervised group, in its own process."""
from __future__ import annotations

from typing import Any

from emos.actors.viz.foxglove import FoxgloveBridgeComponent, FoxgloveConfig


def request(port: int = 8765, host: str = "127.0.0.1", **config: Any) -> FoxgloveConfig:
    return FoxgloveConfig(host=host, port=port, **config)  # validated here, at the recipe's call


def add(launcher: Any, request: FoxgloveConfig) -> None:
    bridge = FoxgloveBridgeComponent(config=request)
    launcher.add_pkg(components=[bridge], package_name="foxglove", multiprocessing=True)
