"""``emos ls``: the recipes this machine has, by name."""
from __future__ import annotations

import argparse
import json

from emos.supervisor.recipes import list_recipes, project_recipes_dir, user_recipes_dir

EXAMPLES = """examples:
  emos ls                 # recipes in ~/emos/recipes/<name>/recipe.py and the project's recipes/
  emos ls --json
  emos info ui_demo && emos run ui_demo
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    parser.add_argument("--json", action="store_true", help="print the list as JSON")


def run(args: argparse.Namespace) -> int:
    recipes = list_recipes()
    if args.json:
        print(json.dumps(recipes, indent=2))
        return 0
    if not recipes:
        print(f"no recipes: put one in {user_recipes_dir()}/<name>/recipe.py")
        return 0
    width = max(len(r["name"]) for r in recipes)
    for source, heading in (("user", f"user recipes ({user_recipes_dir()})"), ("project", f"project recipes ({project_recipes_dir()})")):
        rows = [r for r in recipes if r["source"] == source]
        if not rows:
            continue
        print(heading)
        for r in rows:
            note = "  (hidden by the user recipe of that name)" if r.get("shadowed") else ""
            title = f"{r['title']}: " if r["title"] != r["name"] else ""
            print(f"  {r['name']:<{width}}  {title}{r['description']}{note}")
    return 0
