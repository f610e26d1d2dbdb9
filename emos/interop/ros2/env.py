"""Which ROS 2 this process can use, and making its shared libraries loadable without a shell setup.

Two sources of ROS 2, looked for in this order:

* a sourced install (``/opt/ros/<distro>``; ``$AMENT_PREFIX_PATH`` and ``$ROS_DISTRO`` set by its
  ``setup.bash``), whose libraries live in ``<prefix>/lib``;
* the ROS 2 wheels from PyPI (``pip install 'emos[ros2]'``: ``ros-jazzy-rclpy``, the Kilted
  ``ros-rclpy`` 9.x, ...), whose libraries land in ``<sys.prefix>/lib`` and in
  ``site-packages/ros_*.libs``.

Why we preload with ctypes instead of asking for ``LD_LIBRARY_PATH``: rclpy's C extension names
``librcl.so`` and ~90 more libraries without a path, and the dynamic loader reads
``LD_LIBRARY_PATH`` only when the process starts. A component process is forked from a zygote,
so setting the variable in the running process is too late, and re-executing it would lose what
the supervisor set up. Loading every library of the ROS 2 lib folders with ``RTLD_GLOBAL`` (in
dependency order: a library whose dependencies are not loaded yet is retried after the others)
puts each soname in the process, and the loader then resolves rclpy's and every later
``dlopen``'s dependencies to those copies. ROS 2 itself finds the middleware and type-support
libraries at run time through ``getenv("LD_LIBRARY_PATH")`` (rcpputils' ``find_library_path``),
which does read the variable as changed in the process, so we extend it too. The
``ros-wheels-bootstrapper`` the wheels bring re-executes every Python process with the variable
set; when it (or a sourced shell) already did the work, :func:`ensure_loadable` only checks.

:func:`find` never imports rclpy (cheap: ``emos version`` uses it); :func:`ensure_loadable` makes
``import rclpy`` work and raises :class:`Ros2Unavailable` naming what to install when it cannot.
"""
from __future__ import annotations

import ctypes
import glob
import importlib
import importlib.metadata
import importlib.util
import os
import sys
import sysconfig
from pathlib import Path
from typing import Any

import attrs

from emos.errors import EmosError

INSTALL_HINT = ("install the ROS 2 wheels with `pip install 'emos[ros2]'` (ROS 2 Jazzy: ros-jazzy-rclpy, "
                "ros-jazzy-rmw-fastrtps-cpp and the message packages), or source a ROS 2 install "
                "(`source /opt/ros/jazzy/setup.bash`) before starting EMOS")

# rclpy's major version -> its ROS 2 distribution (for wheels that do not say it in their name).
_RCLPY_DISTRO = {"3": "humble", "4": "humble", "5": "iron", "6": "iron", "7": "jazzy", "8": "kilted", "9": "kilted", "10": "rolling"}


class Ros2Unavailable(EmosError, ImportError):
    """No usable ROS 2 (rclpy and its libraries) in this Python environment."""


@attrs.frozen
class Ros2Install:
    """Where a ROS 2 installation is: ``source`` is ``"wheels"`` or ``"sourced"``; ``lib_dirs``
    the folders its shared libraries are in, first wins."""

    distro: str
    rclpy_version: str
    source: str
    prefix: str
    lib_dirs: tuple[str, ...]
    rmw: str

    def describe(self) -> str:
        """One line: which ROS 2 EMOS uses."""
        where = "pip wheels" if self.source == "wheels" else "sourced install"
        return f"ROS 2 {self.distro} (rclpy {self.rclpy_version}, {self.rmw}) from {where} in {self.prefix}"


def _dist_version(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def _has_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):  # a finder that refuses it, or a half-imported module
        return False


def _wheels() -> Ros2Install | None:
    if not _has_module("rclpy"):
        return None
    version = _dist_version("ros-rclpy")
    if version is None:  # rclpy importable but not from a wheel we know: a sourced install on sys.path
        return None
    # The rclpy that imports decides: a venv with Kilted's wheels over a system with Jazzy's
    # (``--system-site-packages``) still lists the ``ros-jazzy-*`` meta-packages. Their names
    # are used only for an rclpy version we cannot place.
    named = [c for c in ("humble", "iron", "jazzy", "kilted", "rolling") if _dist_version(f"ros-{c}-rclpy") is not None]
    distro = _RCLPY_DISTRO.get(version.split(".")[0]) or (named[0] if named else "unknown")
    prefix = sys.prefix
    purelib = sysconfig.get_paths()["purelib"]
    # The vendored libraries (ros_*.libs) first: the wheels' RPATHs to them do not hold once
    # the libraries sit in <prefix>/lib.
    lib_dirs = sorted(glob.glob(os.path.join(purelib, "ros_*.libs")))
    lib_dirs.append(os.path.join(prefix, "lib"))
    return Ros2Install(distro=distro, rclpy_version=version, source="wheels", prefix=prefix,
                       lib_dirs=tuple(d for d in lib_dirs if os.path.isdir(d)), rmw=_rmw_name())


def _sourced() -> Ros2Install | None:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    distro = os.environ.get("ROS_DISTRO", "")
    if not prefixes and distro:
        prefixes = [f"/opt/ros/{distro}"]
    for prefix in prefixes:
        if glob.glob(os.path.join(prefix, "lib", "python3*", "site-packages", "rclpy")) or \
                glob.glob(os.path.join(prefix, "lib", "python3*", "dist-packages", "rclpy")):
            if not distro:
                distro = Path(prefix).name if Path(prefix).parent.name == "ros" else "unknown"
            version = "?"
            pkg_xml = Path(prefix, "share", "rclpy", "package.xml")
            if pkg_xml.is_file():
                text = pkg_xml.read_text(errors="replace")
                start, end = text.find("<version>"), text.find("</version>")
                if 0 <= start < end:
                    version = text[start + 9:end].strip()
            lib_dirs = tuple(os.path.join(p, "lib") for p in prefixes if os.path.isdir(os.path.join(p, "lib")))
            return Ros2Install(distro=distro, rclpy_version=version, source="sourced", prefix=prefix, lib_dirs=lib_dirs, rmw=_rmw_name())
    return None


def _rmw_name() -> str:
    return os.environ.get("RMW_IMPLEMENTATION") or "rmw_fastrtps_cpp"


def find() -> Ros2Install | None:
    """The ROS 2 this process would use (a sourced install first, then the wheels), or None.
    Imports nothing of ROS 2."""
    return _sourced() or _wheels()


def require() -> Ros2Install:
    """As :func:`find`, raising :class:`Ros2Unavailable` with what to install when there is none."""
    found = find()
    if found is None:
        raise Ros2Unavailable(f"ROS 2 is not available to this Python ({sys.executable}): no rclpy was found; {INSTALL_HINT}")
    return found


def _loader_path_at_start() -> list[str]:
    """``LD_LIBRARY_PATH`` as the dynamic loader saw it: the environment the process started with
    (``os.environ`` may have been changed since, which the loader ignores)."""
    try:
        raw = Path("/proc/self/environ").read_bytes()
    except OSError:
        raw = b""
    for entry in raw.split(b"\0"):
        if entry.startswith(b"LD_LIBRARY_PATH="):
            return [os.path.realpath(p) for p in entry[16:].decode(errors="replace").split(os.pathsep) if p]
    return []


def _needed(path: str) -> list[str]:
    """The DT_NEEDED sonames of an ELF64 little-endian shared library ([] for anything else)."""
    import struct

    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError:
        return []
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        return []
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    sections = [struct.unpack_from("<IIQQQQII", data, shoff + i * shentsize) for i in range(shnum)]
    out = []
    for _name, sh_type, _flags, _addr, offset, size, link, _info in sections:
        if sh_type != 6:  # SHT_DYNAMIC
            continue
        strtab = sections[link][4]
        for pos in range(offset, offset + size, 16):
            tag, val = struct.unpack_from("<qQ", data, pos)
            if tag == 0:
                break
            if tag == 1:  # DT_NEEDED
                end = data.index(b"\0", strtab + val)
                out.append(data[strtab + val:end].decode())
    return out


class _Preloader:
    """Loads libraries of the ROS 2 folders globally, each after the ones it needs, the way the
    loader would have with ``LD_LIBRARY_PATH`` set: only what is asked for and its dependencies
    (loading every library of the folders makes Fast DDS crash the process at exit)."""

    def __init__(self, lib_dirs: tuple[str, ...]):
        self.files: dict[str, str] = {}
        for d in lib_dirs:
            for path in sorted(glob.glob(os.path.join(d, "lib*.so*"))):
                name = os.path.basename(path)
                if not name.startswith("libpython"):  # the interpreter's own: never a second copy
                    self.files.setdefault(name, path)
        self.loaded: dict[str, ctypes.CDLL] = {}  # kept alive: a library must stay for the process's life

    def load_closure(self, path: str) -> None:
        """Load what ``path`` needs from our folders (not ``path`` itself: Python or ROS open it)."""
        for soname in _needed(path):
            self._load(soname, ())

    def _load(self, soname: str, stack: tuple[str, ...]) -> None:
        if soname in self.loaded or soname in stack:
            return
        path = self.files.get(soname)
        if path is None:
            return  # a system library: the loader finds it as usual
        for dep in _needed(path):
            self._load(dep, (*stack, soname))
        self.loaded[soname] = ctypes.CDLL(path, mode=os.RTLD_GLOBAL | os.RTLD_NOW)
        # A library's real file may also be named by a shorter soname (libfoo.so -> libfoo.so.2).
        real = os.path.realpath(path)
        for other, other_path in self.files.items():
            if other not in self.loaded and os.path.realpath(other_path) == real:
                self.loaded[other] = self.loaded[soname]

    def load_package(self, package: str) -> None:
        """What the libraries of a ROS 2 interface package (``sensor_msgs``) need: its Python
        type-support modules are imported, its C type-support libraries opened by ROS by name."""
        for name in list(self.files):
            if name.startswith(f"lib{package}__"):
                self.load_closure(self.files[name])
                self._load(name, ())


_PRELOADER: _Preloader | None = None


_READY: Ros2Install | None = None


def ensure_loadable() -> Ros2Install:
    """Make ``import rclpy`` work in this process; returns the install used. Idempotent.

    Raises :class:`Ros2Unavailable` (what to install) when there is no ROS 2 or it does not load."""
    global _READY
    if _READY is not None:
        return _READY
    install = require()
    current = [p for p in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p]
    missing = [d for d in install.lib_dirs if d not in current]
    if missing:  # for ROS 2's own run-time lookups (rmw and type-support libraries by name)
        os.environ["LD_LIBRARY_PATH"] = os.pathsep.join([*missing, *current])
    if install.source == "sourced":
        os.environ.setdefault("AMENT_PREFIX_PATH", install.prefix)
    global _PRELOADER
    at_start = set(_loader_path_at_start())
    if not all(os.path.realpath(d) in at_start for d in install.lib_dirs):
        _PRELOADER = _Preloader(install.lib_dirs)
        spec = importlib.util.find_spec("rclpy")
        origin = os.path.dirname(spec.origin) if spec is not None and spec.origin else ""
        for ext in sorted(glob.glob(os.path.join(origin, "_rclpy_pybind11*.so"))):
            _PRELOADER.load_closure(ext)
        rmw = _rmw_name()
        if f"lib{rmw}.so" in _PRELOADER.files:
            _PRELOADER._load(f"lib{rmw}.so", ())
        # rmw_dds_common: the graph messages every node publishes; Kilted's rmw opens their type
        # support by name at run time (Jazzy's links it).
        for package in ("builtin_interfaces", "rcl_interfaces", "rosgraph_msgs", "action_msgs", "unique_identifier_msgs",
                        "type_description_interfaces", "service_msgs", "rmw_dds_common"):
            _PRELOADER.load_package(package)
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        raise Ros2Unavailable(f"{install.describe()} is installed but rclpy does not load: {exc}; {INSTALL_HINT}") from exc
    _READY = install
    return install


def prepare_package(package: str) -> None:
    """Call before importing ``<package>.msg`` / ``.srv`` / ``.action`` (a ROS 2 interface package)
    in a process whose loader was not pointed at ROS 2 when it started."""
    if _PRELOADER is not None:
        _PRELOADER.load_package(package)


def message_class(ros_type: str, distro: str) -> Any:
    """rclpy's class of a message type (``sensor_msgs/msg/LaserScan``). Raises ``ImportError``
    whose text names the ROS 2 package to install when rclpy cannot import it."""
    package, _, name = ros_type.partition("/msg/")
    try:
        prepare_package(package)
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError) as exc:
        dist = f"ros-{distro}-{package.replace('_', '-')}"
        raise ImportError(f"{ros_type} needs the ROS 2 package {package}, which rclpy cannot import ({exc}): pip install {dist}") from None


def describe() -> str:
    """One line for ``emos version`` / ``emos run --ros2``: which ROS 2, or that there is none."""
    found = find()
    return found.describe() if found is not None else "ROS 2: not available (pip install 'emos[ros2]' for Jazzy)"
