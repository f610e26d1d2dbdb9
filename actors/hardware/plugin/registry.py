"""Plugins by name, and what each offers (for ``emos robot inspect`` and the docs).

A plugin is found by its short name (the shipped ones below, or an entry point in the
``emos.robot_plugins`` group that an OEM's package declares) or by ``module:Class``.
:func:`describe` reads only the class and a default config: nothing is opened.
"""
from __future__ import annotations

import importlib
from importlib import metadata
from typing import Any

import attrs

from emos.errors import EmosError

from .component import RobotPlugin

__all__ = ["PLUGINS", "UnknownPlugin", "describe", "find_plugin", "plugin_names"]

PLUGINS: dict[str, str] = {
    "create2": "emos.actors.hardware.create2.component:Create2Base",
    "rplidar": "emos.actors.hardware.rplidar.component:Rplidar",
    "feetech": "emos.actors.hardware.feetech.component:FeetechArm",
}
ENTRY_POINT_GROUP = "emos.robot_plugins"


class UnknownPlugin(EmosError, LookupError):
    """No plugin answers to the name (the message lists those that do)."""


def plugin_names() -> dict[str, str]:
    names = dict(PLUGINS)
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        names.setdefault(ep.name, ep.value)
    return names


def find_plugin(name: str) -> type[RobotPlugin]:
    target = plugin_names().get(name, name)
    module_name, sep, attr = target.partition(":")
    if not sep or not module_name or not attr:
        raise UnknownPlugin(f"unknown robot plugin {name!r}: give one of {', '.join(sorted(plugin_names()))} "
                            f"or module:Class")
    try:
        cls = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise UnknownPlugin(f"robot plugin {name!r}: cannot load {target!r}: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, RobotPlugin)):
        raise UnknownPlugin(f"robot plugin {name!r}: {target!r} is not a RobotPlugin subclass")
    return cls


def _value(v: Any) -> Any:
    return v if isinstance(v, (str, int, float, bool, type(None), list, dict)) else repr(v)


def describe(cls: type[RobotPlugin]) -> dict[str, Any]:
    """Topics, actions, events, transports, config and RobotConfig of a plugin class."""
    plugin = cls(component_name=f"{cls.plugin_name or 'plugin'}_inspect")
    config_cls = cls.config_class()
    robot = cls.robot_config()
    return {
        "name": cls.plugin_name, "class": f"{cls.__module__}:{cls.__name__}", "description": cls.description,
        "feedback": {k: {"topic": f.topic, "type": f.msg_type, "help": f.help} for k, f in cls.feedback.items()},
        "commands": {k: {"topic": c.topic, "types": list(c.msg_types), "watchdog": c.timeout, "help": c.help}
                     for k, c in cls.commands.items()},
        "actions": dict(cls.plugin_actions),
        "events": {k: {"on": e.feedback, "when": e.when, "help": e.help} for k, e in cls.plugin_events.items()},
        "transports": {name: t.describe() for name, t in plugin.make_transports().items()},
        "heartbeats": [{"transport": h.transport, "period_s": h.period, "help": h.help} for h in plugin.heartbeats()],
        "config": {"class": config_cls.__name__,
                   "fields": {f.name: _value(getattr(plugin.config, f.name)) for f in attrs.fields(config_cls)}},
        "robot_config": None if robot is None else {f.name: _value(getattr(robot, f.name)) for f in attrs.fields(type(robot))},
    }
