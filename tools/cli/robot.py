"""``emos robot``: the robot plugins on this machine.

    emos robot list
    emos robot inspect create2            # topics, actions, events, transports, config
    emos robot inspect mypkg.base:MyBase --json

Nothing is opened: the plugin's class and its default config are read.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", required=True, metavar="{list,inspect}")
    sub.add_parser("list", help="the plugins this machine has, by name")
    inspect = sub.add_parser("inspect", help="what one plugin offers")
    inspect.add_argument("plugin", help="a plugin name (see `emos robot list`) or module:Class")
    inspect.add_argument("--json", action="store_true", help="print a JSON object")


def run(args: argparse.Namespace) -> int:
    from emos.actors.hardware.plugin.registry import UnknownPlugin, describe, find_plugin, plugin_names

    if args.verb == "list":
        for name, target in sorted(plugin_names().items()):
            print(f"{name:<12} {target}")
        return 0
    try:
        info = describe(find_plugin(args.plugin))
    except UnknownPlugin as exc:
        print(f"emos robot inspect: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(info, indent=2, default=str))
        return 0
    _print(info)
    return 0


def _print(info: dict[str, Any]) -> None:
    print(f"{info['name']}: {info['description']}\n  class: {info['class']}")
    print("feedback (device -> topics):")
    for key, f in info["feedback"].items():
        print(f"  {key:<14} {f['topic']:<20} {f['type']:<14} {f['help']}")
    print("commands (topics -> device):")
    for key, c in info["commands"].items():
        dog = f" (watchdog: config.{c['watchdog']})" if c["watchdog"] else ""
        print(f"  {key:<14} {c['topic']:<20} {'|'.join(c['types']):<14} {c['help']}{dog}")
    print("actions:" if info["actions"] else "actions: none")
    for name, text in info["actions"].items():
        print(f"  {name:<14} {text}")
    print("events:" if info["events"] else "events: none")
    for name, e in info["events"].items():
        print(f"  {name:<14} {e['when']:<32} {e['help']}")
    print("transports:")
    for name, t in info["transports"].items():
        extra = "".join(f" {k}={v}" for k, v in t.items() if k not in ("kind", "device", "address"))
        print(f"  {name:<14} {t['kind']:<8} {t['device']} at {t['address']}{extra}")
    for hb in info["heartbeats"]:
        print(f"  heartbeat on {hb['transport']} every {hb['period_s']} s: {hb['help']}")
    print(f"config ({info['config']['class']}):")
    for name, value in info["config"]["fields"].items():
        print(f"  {name:<20} {value!r}")
    if info["robot_config"] is not None:
        print("robot config:")
        for name, value in info["robot_config"].items():
            print(f"  {name:<20} {value}")
