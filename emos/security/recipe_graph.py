"""What a recipe publishes, subscribes and serves, read from the components it builds.

``emos info`` reads a recipe's syntax tree without running it, which finds the topics written
in the script but not those a component declares by default (a Controller's ``/cmd_vel``). The
access rules need the real ones, so :func:`load_recipe_graph` runs the recipe as
``emos run`` does (as ``__main__``, its folder on ``sys.path``), up to its first
``Launcher.bringup()``, which it replaces by a capture of the launcher: components are built
(their constructors open nothing heavy, by convention) and nothing is started. The recipe's
module-level code does run: load only recipes you would run.

Services a component creates when it configures (``self.create_service`` in
``custom_on_configure``) are read from its code by :mod:`emos.security.configure_services`
(nothing is configured); a name that cannot be read that way is listed in ``RecipeGraph.notes``.
"""
from __future__ import annotations

import logging
import os
import runpy
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from emos.errors import ConfigError

log = logging.getLogger("emos.security")

__all__ = ["RecipeGraph", "ComponentPorts", "load_recipe_graph", "graph_of_launcher"]


@dataclass
class ComponentPorts:
    name: str
    kind: str
    inputs: list[str] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)
    services: list[str] = field(default_factory=list)  # services and action servers, by name


@dataclass
class RecipeGraph:
    recipe: str
    components: list[ComponentPorts]
    notes: list[str] = field(default_factory=list)  # what could not be derived (add it by hand)

    @property
    def outputs(self) -> list[str]:
        return sorted({t for c in self.components for t in c.outputs})

    @property
    def inputs(self) -> list[str]:
        return sorted({t for c in self.components for t in c.inputs})

    @property
    def external_inputs(self) -> list[str]:
        """Inputs no component of the recipe publishes: what someone outside must send (goals,
        commands from an operator)."""
        return sorted(set(self.inputs) - set(self.outputs) - set(self.statuses))

    @property
    def statuses(self) -> list[str]:
        return sorted(f"/{c.name}/status" for c in self.components)

    @property
    def services(self) -> list[str]:
        return sorted({s for c in self.components for s in c.services})


class _Capture:
    """What the replaced ``bringup`` raises, as the code of a ``SystemExit`` (not an Exception: a
    recipe's ``except Exception`` must not swallow it)."""

    def __init__(self, launcher: Any):
        self.launcher = launcher


def _topic_name(topic: Any) -> str:
    name = str(getattr(topic, "name", topic))
    return name if name.startswith("/") else "/" + name


def graph_of_launcher(launcher: Any, recipe: str = "") -> RecipeGraph:
    """The graph of a launcher whose components are added (its shared wiring applied here)."""
    from emos.security.configure_services import configure_services

    launcher._apply_shared()
    comps: list[ComponentPorts] = []
    notes: list[str] = []
    for package in launcher._packages:
        for c in package.components:
            found = configure_services(c)  # created at configure time, read from the code
            services: list[str] = list(found.names)
            notes += [f"{u}: service name unknown until the component runs; add its key to the rules by hand, "
                      "or list the name in the component's declared_services" for u in found.unresolved]
            if getattr(c, "main_srv_type", None) is not None:
                services.append(str(c.main_srv_name))
            try:
                services.extend(str(name) for name in c.action_servers())
            except Exception:  # noqa: BLE001 - a component's own method: a failure only hides its actions
                pass
            comps.append(ComponentPorts(
                name=c.component_name, kind=type(c).__name__,
                inputs=sorted({_topic_name(t) for t in c.in_topics}), outputs=sorted({_topic_name(t) for t in c.out_topics}),
                services=sorted(set(services)),
            ))
    for note in notes:
        log.warning("[security] %s", note)
    return RecipeGraph(recipe=recipe, components=comps, notes=notes)


def load_recipe_graph(path: str | os.PathLike[str], args: list[str] | None = None) -> RecipeGraph:
    """Run the recipe at ``path`` up to its ``Launcher.bringup()`` and return what its components
    declare. Raises :class:`ConfigError` if the recipe never calls ``bringup()``; exceptions of
    the recipe itself propagate (they name its line)."""
    from emos.launcher import Launcher

    path = Path(path).absolute()
    if not path.is_file():
        raise ConfigError(f"recipe {str(path)!r} does not exist")
    original = Launcher.bringup

    def capture(self: Any, duration: float | None = None) -> int:
        raise SystemExit(_Capture(self))

    saved_argv, saved_path, saved_env = sys.argv, list(sys.path), dict(os.environ)
    Launcher.bringup = capture  # type: ignore[method-assign]
    sys.argv = [str(path), *(args or [])]
    sys.path.insert(0, str(path.parent))
    launcher = None
    try:
        runpy.run_path(str(path), run_name="__main__")
    except SystemExit as exc:
        if not isinstance(exc.code, _Capture):
            raise ConfigError(f"recipe {str(path)!r} exited (code {exc.code!r}) before calling Launcher.bringup()") from None
        launcher = exc.code.launcher
    finally:
        Launcher.bringup = original  # type: ignore[method-assign]
        sys.argv, sys.path[:] = saved_argv, saved_path
        os.environ.clear()
        os.environ.update(saved_env)  # a recipe's use_network() etc. must not leak into the caller
    if launcher is None:
        raise ConfigError(f"recipe {str(path)!r} finished without calling Launcher.bringup(): it declares no components to derive a policy from")
    return graph_of_launcher(launcher, str(path))
