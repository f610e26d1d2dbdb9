"""EMOS, the Embodied Operating System, without ROS.

Recipes import from here (``from emos import Launcher, Topic, BaseComponent``) and from
``emos.actors``. Names are resolved lazily so that ``import emos`` stays cheap.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "Launcher": "emos.launcher",
    "BaseComponent": "emos.core.component",
    "Topic": "emos.io.topic",
    "FixedInput": "emos.io.fixed",
    "QoSConfig": "emos.config.qos",
    "BaseComponentConfig": "emos.config.base",
    "ComponentRunType": "emos.config.base",
    "base_validators": "emos.config",
    "ServiceClient": "emos.core.services",
    "ServiceClientConfig": "emos.core.service_config",
    "ComponentFallbacks": "emos.core.component_fallbacks",
    "ActionClient": "emos.core.services",
    "msgs": "emos.msgs",
    "Event": "emos.events.event",
    "Action": "emos.events.action",
    "component_fallback": "emos.core.fallbacks",
    "ComponentStatus": "emos.msgs.status",
    "ComponentServices": "emos.core.reconfig",
    "use_network": "emos.transport.select",
    "NetServiceClient": "emos.transport.zenoh_rpc",
    "NetActionClient": "emos.transport.zenoh_rpc",
    "EmosError": "emos.errors",
    "executable_main": "emos.entrypoint",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'emos' has no attribute {name!r}")
    import importlib

    mod = importlib.import_module(module)
    return mod if name == "msgs" else getattr(mod, name)
