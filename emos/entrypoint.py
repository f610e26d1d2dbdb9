"""``executable_main``: the spec's entry point for a package of components, ported.

Under ROS 2 a package of components needs an executable (``ros_sugar.executable_main``) that the
launcher runs once per component process. EMOS starts component processes itself (by fork, from
the recipe), so a recipe never needs one. A package that keeps its ``executable.py`` still works:
run as a program, it starts one of its components, by class name, under a Launcher of its own::

    python -m my_awesome_pkg.executable --component_type AwesomeComponent --component_name awesome \\
        [--config_file params.toml] [--duration S]

Bad arguments (a class that is not in the lists, a config file that does not exist) are refused
with a message that names them and lists what is known.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from emos.config.base import BaseComponentConfig
from emos.core.component import BaseComponent
from emos.errors import ConfigError

__all__ = ["executable_main"]


def _by_name(kind: str, classes: Sequence[type], base: type) -> dict[str, type]:
    out: dict[str, type] = {}
    for cls in classes:
        if not (isinstance(cls, type) and issubclass(cls, base)):
            raise ConfigError(f"executable_main: list_of_{kind} takes {base.__name__} subclasses, got {cls!r}")
        out[cls.__name__] = cls
    return out


def executable_main(*, list_of_components: Sequence[type], list_of_configs: Sequence[type] = (),
                    argv: Sequence[str] | None = None) -> int:
    """Start one component of ``list_of_components`` (chosen by ``--component_type``) under a
    Launcher and run it until SIGINT/SIGTERM (or ``--duration`` s); returns the exit code."""
    components = _by_name("components", list_of_components, BaseComponent)
    configs = _by_name("configs", list_of_configs, BaseComponentConfig)
    if not components:
        raise ConfigError("executable_main: list_of_components is empty; give the component classes this package offers")
    parser = argparse.ArgumentParser(description="Run one component of this package under EMOS.")
    parser.add_argument("--component_type", required=True, help=f"one of: {', '.join(sorted(components))}")
    parser.add_argument("--component_name", help="the component's name (default: the class name in snake case)")
    parser.add_argument("--config_type", help=f"its config class, one of: {', '.join(sorted(configs)) or '(none given)'}")
    parser.add_argument("--config_file", help="a TOML/YAML/JSON file of parameters (docs/config.md)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    args = parser.parse_args(argv)
    cls = components.get(args.component_type)
    if cls is None:
        parser.error(f"--component_type {args.component_type!r} is not one of this package's components: {', '.join(sorted(components))}")
    kwargs: dict[str, Any] = {"component_name": args.component_name or _snake(args.component_type)}
    if args.config_type:
        config_cls = configs.get(args.config_type)
        if config_cls is None:
            parser.error(f"--config_type {args.config_type!r} is not one of this package's configs: {', '.join(sorted(configs)) or '(none given)'}")
        kwargs["config"] = config_cls()
    if args.config_file:
        if not Path(args.config_file).is_file():
            parser.error(f"--config_file {args.config_file!r}: no such file")
        kwargs["config_file"] = args.config_file
    component = cls(**kwargs)
    from emos.launcher import Launcher

    launcher = Launcher()
    launcher.add_pkg(components=[component], multiprocessing=True)
    return launcher.bringup(duration=args.duration)


def _snake(name: str) -> str:
    return "".join(f"_{c.lower()}" if c.isupper() and i else c.lower() for i, c in enumerate(name))


if __name__ == "__main__":  # pragma: no cover - a library module
    sys.exit("emos.entrypoint is a library: call executable_main() from your package's executable")
