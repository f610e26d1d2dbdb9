"""The benchmark-only virtual environment that peers from other projects run in.

Benchmarks compare EMOS with what a robotics engineer would pick instead (iceoryx2, zenoh and
dora for ``emos bench ipc``; OpenKarto, the scan matcher of slam_toolbox, for ``emos bench
slam``; Nav2's AMCL for ``emos bench localize``). Their packages go into one virtual environment that this module creates (``python -m
venv``, then ``pip install`` of pinned versions) under ``$EMOS_BENCH_PEERS`` (default
``~/.cache/emos-bench/peers``): never a dependency of EMOS, never imported by it; a peer runs as a
script of its own with that environment's Python. A registry that cannot be reached, or a package
that installs but cannot run here, is a clear error naming the peer and its packages.
"""
from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from emos.errors import EmosError

ENV_PEER_DIR = "EMOS_BENCH_PEERS"
INSTALL_TIMEOUT_S = 900.0


class PeerUnavailable(EmosError, RuntimeError):
    """A peer that cannot be measured here (its packages do not install, or it is unknown)."""


def peer_dir() -> Path:
    return Path(os.environ.get(ENV_PEER_DIR) or "~/.cache/emos-bench/peers").expanduser()


def peer_python() -> Path:
    return peer_dir() / "bin" / "python"


def peer_env_has(module: str) -> bool:
    """Whether the peer environment exists and imports ``module`` (no install attempted)."""
    python = peer_python()
    if not python.exists():
        return False
    return subprocess.run([str(python), "-c", f"import {module}"], capture_output=True, timeout=120).returncode == 0


def ensure(peer: str, packages: list[str], module: str, *, log: Callable[[str], Any] | None = None,
           command_problem: Callable[[], str | None] = lambda: None) -> Path:
    """The peer environment's Python with ``packages`` installed (``module`` imports, and
    ``command_problem()`` finds nothing wrong), creating and filling the environment if needed."""
    python = peer_python()
    if peer_env_has(module) and command_problem() is None:
        return python
    where = peer_dir()
    if log:
        log(f"installing {' '.join(packages)} into the benchmark-only environment {where} (once)...")
    if not python.exists():
        where.parent.mkdir(parents=True, exist_ok=True)
        made = subprocess.run([sys.executable, "-m", "venv", str(where)], capture_output=True, text=True, timeout=INSTALL_TIMEOUT_S)
        if made.returncode != 0:
            raise PeerUnavailable(f"peer {peer}: cannot create the virtual environment {where}: {made.stderr.strip()[-400:]}")
    try:
        pip = subprocess.run([str(python), "-m", "pip", "install", "--disable-pip-version-check", "-q", *packages],
                             capture_output=True, text=True, timeout=INSTALL_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise PeerUnavailable(f"peer {peer}: pip install {' '.join(packages)} into {where} did not finish in {INSTALL_TIMEOUT_S:.0f} s "
                              "(is the package registry reachable?)") from None
    if pip.returncode != 0 or not peer_env_has(module):
        detail = (pip.stderr or pip.stdout).strip().splitlines()[-3:]
        raise PeerUnavailable(f"peer {peer}: cannot install {' '.join(packages)} into {where} (the package registry may be "
                              f"unreachable): {' | '.join(detail) or 'no output'}")
    problem = command_problem()
    if problem:
        raise PeerUnavailable(f"peer {peer}: {' '.join(packages)} installed into {where}, but {problem}")
    return python


def run_script(peer: str, python: Path, script: Path, args: list[str], timeout_s: float) -> dict[str, Any]:
    """Run a peer's script (``tools/bench/*_peer_*.py``) with the peer environment's ``python``
    and return the JSON object it prints last; a time-out, a failure or no such line is a
    PeerUnavailable naming the peer and what went wrong."""
    import json

    try:
        done = subprocess.run([str(python), str(script), *args], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise PeerUnavailable(f"peer {peer}: no result in {timeout_s:.0f} s") from None
    if done.returncode != 0:
        raise PeerUnavailable(f"peer {peer} failed (exit {done.returncode}): {done.stderr.strip()[-400:]}")
    try:
        doc = json.loads(done.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        doc = None
    if not isinstance(doc, dict):
        raise PeerUnavailable(f"peer {peer} printed no result: {done.stdout[-200:]!r}")
    return doc
