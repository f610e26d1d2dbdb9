"""Package share directories: EMOS's ``ament_index_python.packages.get_package_share_directory``.

ROS recipes find shipped files (maps, parameter files) through the package's share directory::

    from ament_index_python.packages import get_package_share_directory
    kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")
    map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")

Those lines port by changing the import only::

    from emos.packages import get_package_share_directory

The directories belong to higher layers (the simulator ships the ``kompass_sim`` maps), which this
core must not import (DESIGN.md, "Layout"; tests/test_layers.py). Each one declares a Python entry
point in the group ``emos.packages`` (pyproject's ``[project.entry-points."emos.packages"]``),
``<package name> = <module>``: the share directory is that module's folder (a package's
``__init__.py`` folder, like ament's ``share/<package>``). A name nobody registered is a
:class:`PackageNotFoundError` listing the names that are registered.
"""
from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

from emos.errors import EmosError

__all__ = ["GROUP", "PackageNotFoundError", "get_package_share_directory", "get_packages_with_share_directories"]

GROUP = "emos.packages"


class PackageNotFoundError(EmosError, KeyError):
    """No package of that name registered a share directory (ament raises its own
    ``PackageNotFoundError``, a KeyError, so ``except KeyError`` keeps working)."""

    def __str__(self) -> str:  # KeyError's str() would quote the whole message
        return str(self.args[0]) if self.args else ""


def get_packages_with_share_directories() -> list[str]:
    """The package names registered in the ``emos.packages`` entry points, sorted."""
    from importlib.metadata import entry_points  # here: only a recipe that asks pays for the scan

    return sorted({ep.name for ep in entry_points(group=GROUP)})


def _directory_of(name: str, value: str, target: object) -> Path:
    if isinstance(target, ModuleType):
        where = getattr(target, "__file__", None)
        if where is None:  # a namespace package has no __init__.py: its one folder is the share directory
            folders = list(getattr(target, "__path__", []))
            if len(folders) != 1:
                raise PackageNotFoundError(f"package {name!r} ({value}) is a namespace package spread over "
                                           f"{len(folders)} folders; its share directory must be one folder")
            return Path(folders[0])
        return Path(where).resolve().parent
    if isinstance(target, (str, os.PathLike)):
        return Path(target)
    raise PackageNotFoundError(f"package {name!r}: entry point {value!r} in group {GROUP!r} names a "
                               f"{type(target).__name__}; it must name a module (whose folder is the share "
                               f"directory) or a path")


def get_package_share_directory(package_name: str, print_warning: bool = True) -> str:
    """The share directory of ``package_name`` (an absolute path, as a str like ament's).

    ``print_warning`` is accepted for ament's signature and ignored. Raises
    :class:`PackageNotFoundError` naming the package and the registered ones when nobody
    registered it, when its entry point cannot be imported, or when the directory is missing.
    """
    from importlib.metadata import entry_points

    if not isinstance(package_name, str) or not package_name:
        raise TypeError(f"get_package_share_directory: package_name must be a non-empty str, got {package_name!r}")
    found = {ep.value: ep for ep in entry_points(group=GROUP, name=package_name)}  # one install seen twice: same value
    if not found:
        known = ", ".join(get_packages_with_share_directories()) or "none"
        raise PackageNotFoundError(
            f"package {package_name!r} not found: no share directory is registered under that name (entry point "
            f"group {GROUP!r}); known packages: {known}. (In a source checkout, re-run `pip install -e .` so its "
            "entry points are registered.)")
    if len(found) > 1:
        raise PackageNotFoundError(f"package {package_name!r} is registered more than once in group {GROUP!r} "
                                   f"({', '.join(sorted(found))}): uninstall all but one")
    (entry,) = found.values()
    try:
        target = entry.load()
    except ImportError as exc:
        raise PackageNotFoundError(f"package {package_name!r}: its share directory's entry point ({entry.value}) "
                                   f"cannot be imported: {exc}") from exc
    directory = _directory_of(package_name, entry.value, target).resolve()
    if not directory.is_dir():
        raise PackageNotFoundError(f"package {package_name!r}: share directory {str(directory)!r} "
                                   f"({entry.value}) does not exist")
    return str(directory)
