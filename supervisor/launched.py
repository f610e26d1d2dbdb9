"""Waiting for a system started with ``emos run`` in a child process to come up.

Benchmarks and harnesses (``emos bench navloop``, ``bench sim --component``, BARN through the
processes) start a recipe as a subprocess and must know when its run directory exists and its
components are active; if the process dies first, they say so with the end of its log.
"""
from __future__ import annotations

import subprocess
import time
from pathlib import Path
from typing import Any

from emos.errors import EmosError


class SystemFailed(EmosError, RuntimeError):
    """The launched system exited, or did not come up in time."""


def log_tail(path: Path, lines: int = 40) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError as exc:
        return f"(no log: {exc})"


def _check_alive(proc: subprocess.Popen, log_path: Path, what: str) -> None:
    if proc.poll() is not None:
        raise SystemFailed(f"{what}: the system exited with {proc.returncode}:\n{log_tail(log_path)}")


def wait_run_dir(proc: subprocess.Popen, log_path: Path, what: str, timeout: float = 60.0) -> Path:
    """The run directory of the ``emos run`` in ``proc``, once its supervisor socket exists."""
    from emos.transport.context import runtime_root

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        _check_alive(proc, log_path, what)
        for d in runtime_root().iterdir():
            if d.name.startswith(f"{proc.pid}-") and (d / "supervisor.sock").exists():
                return d
        time.sleep(0.05)
    raise SystemFailed(f"{what}: the system did not come up within {timeout:.0f} s:\n{log_tail(log_path)}")


def component_states(tree: dict) -> dict[str, str]:
    """Component name -> lifecycle state, from the supervisor's ``tree`` answer."""
    states: dict[str, str] = {}

    def walk(node: dict) -> None:
        if "state" in node and "name" in node:
            states[node["name"]] = node["state"]
        for child in node.get("children", []):
            walk(child)

    walk(tree)
    return states


def wait_active(rpc: Any, proc: subprocess.Popen, log_path: Path, components: tuple[str, ...] | list[str],
                what: str, timeout: float = 60.0) -> None:
    """Until every one of ``components`` is active (``rpc``: a client of the supervisor socket)."""
    end = time.monotonic() + timeout
    states: dict[str, str] = {}
    while time.monotonic() < end:
        _check_alive(proc, log_path, what)
        try:
            states = component_states(rpc.call("tree")["tree"])
        except (OSError, ConnectionError, KeyError):
            pass
        if all(states.get(c) == "active" for c in components):
            return
        time.sleep(0.1)
    raise SystemFailed(f"{what}: components not active within {timeout:.0f} s ({states}):\n{log_tail(log_path)}")
