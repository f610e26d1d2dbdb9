"""Maps the fixed top-level folders into the ``emos`` namespace.

``actors/``, ``supervisor/`` and ``chaos/`` live at the top of the repository but import as
``emos.actors``, ``emos.supervisor`` and ``emos.chaos``: a top-level ``supervisor`` package
would shadow supervisord's, which many robots have installed.
"""
from pathlib import Path

from setuptools import setup

ROOTS = {"emos": "emos", "emos.actors": "actors", "emos.supervisor": "supervisor", "emos.chaos": "chaos"}


def _packages() -> tuple[list[str], dict[str, str]]:
    packages, package_dir = [], {}
    for pkg, folder in ROOTS.items():
        package_dir[pkg] = folder
        for init in sorted(Path(folder).rglob("__init__.py")):
            rel = init.parent.relative_to(folder).parts
            if "__pycache__" not in rel:
                packages.append(".".join((pkg, *rel)))
    return packages, package_dir


packages, package_dir = _packages()
setup(packages=packages, package_dir=package_dir, package_data={"": ["py.typed", "*.json", "*.yaml", "*.tsv", "*.pgm", "*.png", "*.urdf", "*.html", "*.js", "*.css", "LICENSE"]})
