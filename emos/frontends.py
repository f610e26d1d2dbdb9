"""Optional frontends register themselves; the Launcher finds them by name.

The web UI (``Launcher.enable_ui``) and the Foxglove live view (``Launcher.enable_foxglove``)
are actors, a tier above this core: the Launcher must not import them (DESIGN.md, "Layout";
tests/test_layers.py). Each one declares a Python entry point in the group ``emos.frontends``
(pyproject's ``[project.entry-points."emos.frontends"]``), whose object has two functions:

* ``request(**options)``: check the recipe's call at once, where the recipe makes it, and return
  what ``add`` needs (raises ``TypeError``/``ValueError`` naming the bad option);
* ``add(launcher, request)``: add the frontend's components to the launcher as a supervised group.

A frontend that is not installed, or whose dependencies are missing, is a
:class:`FrontendUnavailable` naming it and the extra that brings it.
"""
from __future__ import annotations

from typing import Any, Protocol

from emos.errors import EmosError

GROUP = "emos.frontends"

# The pip extra that brings each shipped frontend's dependencies, for the error message.
EXTRAS = {"ui": "ui", "foxglove": "ecosystem", "ros2": "ros2"}


class Frontend(Protocol):
    def request(self, **options: Any) -> Any: ...

    def add(self, launcher: Any, request: Any) -> None: ...


class FrontendUnavailable(EmosError, ImportError):
    """A frontend the recipe asked for (``enable_ui``, ``enable_foxglove``) cannot be loaded: it is
    not registered in this installation, or importing it failed. ImportError as before the hook,
    when the Launcher imported the frontend's module itself."""


def _install_hint(name: str) -> str:
    extra = EXTRAS.get(name)
    install = f"pip install 'emos[{extra}]'" if extra else "install the package that provides it"
    # A source checkout installed before the entry point existed has no record of it.
    return f"{install} (in a source checkout, re-run `pip install -e .` so its entry points are registered)"


def load_frontend(name: str) -> Frontend:
    """The frontend registered as ``name`` in the ``emos.frontends`` entry points, imported."""
    from importlib.metadata import entry_points  # here: only a recipe that asks for a frontend pays for it

    found = {ep.value: ep for ep in entry_points(group=GROUP, name=name)}  # one install seen twice: same value
    if not found:
        raise FrontendUnavailable(f"the EMOS frontend {name!r} is not installed (no entry point {name!r} in group "
                                  f"{GROUP!r}): {_install_hint(name)}")
    if len(found) > 1:
        raise FrontendUnavailable(f"the EMOS frontend {name!r} is registered more than once in group {GROUP!r} "
                                  f"({', '.join(sorted(found))}): uninstall all but one")
    (entry,) = found.values()
    try:
        frontend: Frontend = entry.load()
    except ImportError as exc:
        raise FrontendUnavailable(f"the EMOS frontend {name!r} ({entry.value}) cannot be imported: {exc}; "
                                  f"{_install_hint(name)}") from exc
    for method in ("request", "add"):
        if not callable(getattr(frontend, method, None)):
            raise FrontendUnavailable(f"the EMOS frontend {name!r} ({entry.value}) has no {method}() function; "
                                      f"a frontend provides request(**options) and add(launcher, request)")
    return frontend
