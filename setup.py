"""Maps the fixed top-level folders into the ``emos`` namespace.

``actors/``, ``supervisor/``, ``chaos/`` and ``tools/`` live at the top of the repository but import
as ``emos.actors``, ``emos.supervisor``, ``emos.chaos`` and ``emos.tools``: a top-level ``supervisor`` package
would shadow supervisord's, which many robots have installed.
"""
from pathlib import Path

from setuptools import Extension, setup

ROOTS = {"emos": "emos", "emos.actors": "actors", "emos.supervisor": "supervisor", "emos.chaos": "chaos", "emos.tools": "tools"}


def _packages() -> tuple[list[str], dict[str, str]]:
    packages, package_dir = [], {}
    for pkg, folder in ROOTS.items():
        package_dir[pkg] = folder
        for init in sorted(Path(folder).rglob("__init__.py")):
            rel = init.parent.relative_to(folder).parts
            if "__pycache__" not in rel:
                packages.append(".".join((pkg, *rel)))
    return packages, package_dir


def _extensions() -> list[Extension]:
    """The C fast paths: the codec's (emos/msgs/_ccodec.c) and the swept-footprint check's inner
    loop (actors/nav/safety/_cswept.c). Optional: without a C compiler or numpy's headers the
    install goes on, and the Python versions give the same answers alone."""
    try:
        import numpy
    except ImportError:
        return []
    headers = [numpy.get_include()]
    return [Extension("emos.msgs._ccodec", ["emos/msgs/_ccodec.c"], include_dirs=headers, optional=True, extra_compile_args=["-O2"]),
            # -O3: the per-point loops vectorize; no -ffast-math, which would change the answers.
            Extension("emos.actors.nav.safety._cswept", ["actors/nav/safety/_cswept.c"], include_dirs=headers, optional=True,
                      extra_compile_args=["-O3"])]


packages, package_dir = _packages()
setup(ext_modules=_extensions(), packages=packages, package_dir=package_dir, package_data={"": ["py.typed", "*.pyi", "*.json", "*.yaml", "*.tsv", "*.pgm", "*.png", "*.urdf", "*.html", "*.js", "*.css", "LICENSE"]})
