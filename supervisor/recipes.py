"""Where recipes and run logs live, and how a recipe is found by name.

A recipe is either a script in the project's ``recipes/`` folder (``recipes/ui_demo.py`` is
``ui_demo``) or a folder in the user's recipe folder (``~/emos/recipes/<name>/recipe.py``, with an
optional ``manifest.json`` giving a display name and description). ``$EMOS_HOME`` moves ``~/emos``.
"""
from __future__ import annotations

import ast
import json
import os
from pathlib import Path
from typing import Any

from emos.errors import EmosError

ENV_HOME = "EMOS_HOME"


class RecipeNotFound(EmosError, LookupError):
    pass


def emos_home() -> Path:
    return Path(os.environ.get(ENV_HOME) or Path.home() / "emos").expanduser()


def user_recipes_dir() -> Path:
    return emos_home() / "recipes"


def logs_dir() -> Path:
    return emos_home() / "logs"


def project_recipes_dir() -> Path | None:
    """The ``recipes/`` folder beside the installed ``emos`` package (a source checkout), if any."""
    import emos

    folder = Path(emos.__file__).resolve().parent.parent / "recipes"
    return folder if folder.is_dir() else None


def _docstring_line(path: Path) -> str:
    try:
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
    except (SyntaxError, UnicodeDecodeError, OSError):
        return ""
    return doc.strip().splitlines()[0] if doc else ""


def list_recipes() -> list[dict[str, Any]]:
    """Every recipe found: name, path, where it comes from, and a one-line description."""
    found: list[dict[str, Any]] = []
    user = user_recipes_dir()
    if user.is_dir():
        for folder in sorted(p for p in user.iterdir() if p.is_dir()):
            script = folder / "recipe.py"
            if not script.is_file():
                continue
            entry = {"name": folder.name, "path": str(script), "source": "user", "title": folder.name, "description": ""}
            manifest = folder / "manifest.json"
            if manifest.is_file():
                try:
                    data = json.loads(manifest.read_text(encoding="utf-8"))
                    entry["title"] = str(data.get("name") or folder.name)
                    entry["description"] = str(data.get("description") or "")
                except (ValueError, OSError) as exc:
                    entry["description"] = f"(manifest.json unreadable: {exc})"
            entry["description"] = entry["description"] or _docstring_line(script)
            found.append(entry)
    project = project_recipes_dir()
    if project is not None:
        taken = {e["name"] for e in found}
        for script in sorted(project.glob("*.py")):
            if script.stem.startswith("_"):
                continue
            found.append({"name": script.stem, "path": str(script), "source": "project", "title": script.stem,
                          "description": _docstring_line(script), "shadowed": script.stem in taken})
    return found


def resolve_recipe(name_or_path: str) -> Path:
    """The script of a recipe given by path or by name (the user's recipes first, then the project's)."""
    candidate = Path(name_or_path).expanduser()
    if candidate.is_file():
        return candidate
    if candidate.is_dir() and (candidate / "recipe.py").is_file():
        return candidate / "recipe.py"
    if os.sep not in name_or_path and not name_or_path.endswith(".py"):
        for entry in list_recipes():
            if entry["name"] == name_or_path:
                return Path(entry["path"])
    names = sorted({e["name"] for e in list_recipes()})
    raise RecipeNotFound(f"no recipe {name_or_path!r}: not a file, and not a recipe name"
                         f" ({'known: ' + ', '.join(names) if names else 'no recipes in ' + str(user_recipes_dir())}; see `emos ls`)")
