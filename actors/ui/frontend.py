"""The web UI as a Launcher frontend: entry point ``ui`` in the group ``emos.frontends``
(see emos/frontends.py). ``Launcher.enable_ui`` calls ``request`` when the recipe asks for the UI
and ``add`` at bringup, once every component is known (the UI shows them all)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from emos.actors.ui.launch import add_ui, check_ui_request


def request(inputs: Sequence[Any] | None = None, outputs: Sequence[Any] | None = None, port: int = 5001,
            host: str = "127.0.0.1", **settings: Any) -> dict[str, Any]:
    return check_ui_request(inputs, outputs, port, host, settings)


def add(launcher: Any, request: dict[str, Any]) -> None:
    add_ui(launcher, request)
