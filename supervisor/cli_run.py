"""``emos run RECIPE.py``: execute a recipe as ``__main__`` under the supervisor."""
from __future__ import annotations

import argparse
import os
import runpy
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recipe", help="recipe name (see `emos ls`) or path of the recipe script")
    parser.add_argument("--duration", type=float, default=None, help="stop by itself after this many seconds")
    parser.add_argument("--no-log", action="store_true", help="do not keep a copy of the output in ~/emos/logs")
    parser.add_argument("args", nargs="*", help="arguments for the recipe, after '--'")


def run(args: argparse.Namespace) -> int:
    from emos.supervisor.recipes import RecipeNotFound, resolve_recipe

    try:
        path = resolve_recipe(args.recipe)
    except RecipeNotFound as exc:
        print(f"emos run: {exc}", file=sys.stderr)
        return 2
    if args.duration is not None and args.duration <= 0:
        print("emos run: --duration must be > 0 seconds", file=sys.stderr)
        return 2
    if not args.no_log:
        from emos.supervisor.runlog import start_run_log

        start_run_log(path, sys.argv[1:])
    import emos.launcher as launcher_mod

    launcher_mod._RUN_DURATION = args.duration
    os.environ["EMOS_RUN_CLI"] = "1"
    sys.argv = [str(path), *args.args]
    sys.path.insert(0, str(path.resolve().parent))
    runpy.run_path(str(path), run_name="__main__")
    code = launcher_mod.Launcher.last_exit_code
    return 0 if code is None else code
