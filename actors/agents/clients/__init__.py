"""Model clients: one interface (check_connection, initialize, inference, deinitialize) over
OpenAI-compatible servers, Ollama, RoboML (HTTP, WebSocket, RESP) and LeRobot (gRPC)."""
from __future__ import annotations

import importlib
from typing import Any

from .base import CLIENT_TYPES, ModelClient, client_from_serialized

# public name -> defining submodule; imported on first use so optional deps stay optional.
_LAZY = {
    "GenericHTTPClient": ".generic",
    "OllamaClient": ".ollama",
    "RoboMLHTTPClient": ".roboml",
    "RoboMLWSClient": ".roboml_ws",
    "RoboMLRESPClient": ".roboml_resp",
    "LeRobotClient": ".lerobot",
    "AsyncClient": ".aio",
}

__all__ = ["ModelClient", "client_from_serialized", "CLIENT_TYPES", *_LAZY]


def _register_all() -> None:
    """Import every client module so CLIENT_TYPES knows all classes."""
    for module in set(_LAZY.values()):
        try:
            importlib.import_module(module, __name__)
        except ModuleNotFoundError:
            continue


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value
