"""``emos info NAME|FILE``: what a recipe needs, read from its source without running it.

Every ``Topic(name=..., msg_type=...)`` in the script is found in its syntax tree; topics of
sensor types are the sensors the robot must provide, the others are listed apart. Names and
types given as plain strings (or variables holding one) are resolved; anything computed at run
time is shown as such.
"""
from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path
from typing import Any

from emos.supervisor.recipes import RecipeNotFound, resolve_recipe

# Sensor message types and the hardware that usually provides them.
SENSORS: dict[str, str] = {
    "Image": "camera", "CompressedImage": "camera (compressed)", "RGBD": "depth camera (RGB-D)",
    "LaserScan": "2D lidar", "PointCloud2": "3D lidar or depth camera", "Imu": "IMU",
    "Audio": "microphone", "Odometry": "wheel odometry or localization", "CameraInfo": "camera calibration",
}

EXAMPLES = """examples:
  emos info ui_demo                 # a recipe by name (see `emos ls`)
  emos info ./my_recipe.py --json   # a file
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    parser.add_argument("recipe", help="recipe name or path of a recipe script")
    parser.add_argument("--json", action="store_true", help="print the requirements as JSON")


def _short_type(name: str) -> str:
    return name.rsplit("/", 1)[-1]


class _Reader(ast.NodeVisitor):
    def __init__(self) -> None:
        self.strings: dict[str, str] = {}  # module-level NAME = "literal"
        self.topics: list[dict[str, Any]] = []
        self.ui: dict[str, Any] | None = None
        self.components: list[str] = []

    def _value(self, node: ast.AST | None) -> str | None:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value
        if isinstance(node, ast.Name) and node.id in self.strings:
            return self.strings[node.id]
        if isinstance(node, ast.JoinedStr):
            return None
        return None

    def visit_Assign(self, node: ast.Assign) -> None:
        if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    self.strings[target.id] = node.value.value
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        func = node.func
        name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        kwargs = {k.arg: k.value for k in node.keywords if k.arg}
        if name == "Topic":
            topic_name = self._value(kwargs.get("name", node.args[0] if node.args else None))
            msg_type = kwargs.get("msg_type", node.args[1] if len(node.args) > 1 else None)
            type_name = self._value(msg_type)
            if type_name is None and isinstance(msg_type, (ast.Name, ast.Attribute)):
                type_name = msg_type.id if isinstance(msg_type, ast.Name) else msg_type.attr
            self.topics.append({"name": topic_name or "<computed at run time>", "type": _short_type(type_name) if type_name else "<computed>",
                                "line": node.lineno})
        elif name == "enable_ui":
            port = kwargs.get("port")
            self.ui = {"line": node.lineno, "port": port.value if isinstance(port, ast.Constant) else 5001 if port is None else "<computed>"}
        elif "component_name" in kwargs:
            comp = self._value(kwargs["component_name"])
            self.components.append(f"{comp or '<computed>'} ({name})")
        self.generic_visit(node)


def inspect_recipe(path: Path) -> dict[str, Any]:
    """Requirements of the recipe at ``path``; raises SyntaxError (with its line) if it does not parse."""
    source = path.read_text(encoding="utf-8")
    tree = ast.parse(source, filename=str(path))
    reader = _Reader()
    reader.visit(tree)
    unique: dict[tuple[str, str], dict[str, Any]] = {}
    for t in reader.topics:
        unique.setdefault((t["name"], t["type"]), t)
    topics = list(unique.values())
    sensors = [dict(t, hardware=SENSORS[t["type"]]) for t in topics if t["type"] in SENSORS]
    others = [t for t in topics if t["type"] not in SENSORS]
    return {"recipe": str(path), "description": (ast.get_docstring(tree) or "").strip().split("\n")[0],
            "sensors": sensors, "other_topics": others, "components": reader.components, "web_ui": reader.ui}


def run(args: argparse.Namespace) -> int:
    try:
        path = resolve_recipe(args.recipe)
        info = inspect_recipe(path)
    except RecipeNotFound as exc:
        print(f"emos info: {exc}", file=sys.stderr)
        return 2
    except SyntaxError as exc:
        where = f"{exc.filename}:{exc.lineno}" + (f":{exc.offset}" if exc.offset else "")
        print(f"emos info: {where}: syntax error: {exc.msg}", file=sys.stderr)
        if exc.text:
            print("    " + exc.text.rstrip("\n"), file=sys.stderr)
            if exc.offset:
                print("    " + " " * (exc.offset - 1) + "^", file=sys.stderr)
        print("emos info: nothing was run", file=sys.stderr)
        return 2
    except (OSError, UnicodeDecodeError) as exc:
        print(f"emos info: cannot read {args.recipe}: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"recipe: {info['recipe']}")
    if info["description"]:
        print(f"  {info['description']}")
    print("\nrequired sensors:")
    for t in info["sensors"] or []:
        print(f"  {t['name']:<32} {t['type']:<16} {t['hardware']}")
    if not info["sensors"]:
        print("  none")
    print("\nother topics:")
    for t in info["other_topics"]:
        print(f"  {t['name']:<32} {t['type']}")
    if not info["other_topics"]:
        print("  none")
    if info["components"]:
        print("\ncomponents:\n  " + "\n  ".join(info["components"]))
    if info["web_ui"]:
        print(f"\nweb UI: yes (port {info['web_ui']['port']}, line {info['web_ui']['line']})")
    return 0
