"""Lazy imports of the simulation's heavy optional dependencies.

``import emos.actors.sim`` must stay cheap (the CLI imports plug-ins lazily), so pybullet,
Pillow and scipy are only imported by the functions that need them.
"""
from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from types import ModuleType

_EXTRA_HINT = "install the simulation extra: pip install 'emos[sim]'"


def pybullet() -> ModuleType:
    """The pybullet module, or an ImportError naming the extra to install."""
    try:
        import pybullet as module
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"emos.actors.sim needs pybullet; {_EXTRA_HINT}") from exc
    return module


def bullet_client() -> type:
    """``pybullet_utils.bullet_client.BulletClient``: one physics server per World."""
    pybullet()
    from pybullet_utils import bullet_client as module

    return module.BulletClient


def pybullet_data_path() -> str:
    try:
        import pybullet_data
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"emos.actors.sim needs pybullet_data; {_EXTRA_HINT}") from exc
    return pybullet_data.getDataPath()


def pil_image() -> ModuleType:
    try:
        from PIL import Image
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"simulator pictures (top-down maps, JPEG frames, textures) need Pillow; {_EXTRA_HINT}") from exc
    return Image


def pil_draw() -> ModuleType:
    pil_image()
    from PIL import ImageDraw

    return ImageDraw


def scipy_csgraph() -> ModuleType:
    try:
        from scipy.sparse import csgraph
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"the built-in navigator needs scipy; {_EXTRA_HINT}") from exc
    return csgraph


def scipy_ndimage() -> ModuleType:
    try:
        from scipy import ndimage
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"the built-in navigator needs scipy; {_EXTRA_HINT}") from exc
    return ndimage


@contextlib.contextmanager
def c_stdout_silenced() -> Iterator[None]:
    """Silence writes to file descriptor 1 from C code (pybullet prints ``argv[0]=`` on
    connect), which would otherwise corrupt machine-readable output such as ``--json``."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no usable fd 1 (embedded interpreters): nothing to protect
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
