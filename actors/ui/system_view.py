"""The supervision tree as the page shows it, and the start/stop/restart buttons.

Stop and start are the lifecycle's deactivate and activate (the process stays up, its topics
stay open); restart is asked of the supervisor, which starts a fresh process and counts the
restart as requested (by the UI), not as a crash.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from emos.core import control as C
from emos.core.rpc import AsyncRpcClient

ACTIONS = ("start", "stop", "restart")


class SystemView:
    def __init__(self, supervisor_socket: str | None, control_socket: Callable[[str], Path], own_name: str):
        self.supervisor_socket = supervisor_socket
        self.control_socket = control_socket
        self.own_name = own_name
        self._cpu: dict[int, tuple[float, float]] = {}  # pid -> (cpu seconds, wall time)

    async def snapshot(self) -> dict[str, Any]:
        if not self.supervisor_socket:
            raise ConnectionError("this UI runs without a supervisor")
        client = AsyncRpcClient(self.supervisor_socket)
        try:
            data = await client.call("tree", timeout=3.0)
        finally:
            await client.close()
        now = time.monotonic()
        seen: dict[int, tuple[float, float]] = {}

        def walk(node: dict[str, Any]) -> None:
            pid, cpu_s = node.get("pid"), node.get("cpu_s")
            if pid and cpu_s is not None:
                before = self._cpu.get(pid)
                if before is not None and now > before[1]:
                    node["cpu_percent"] = round(100.0 * (cpu_s - before[0]) / (now - before[1]), 1)
                seen[pid] = (cpu_s, now)
            for child in node.get("children", []):
                walk(child)

        walk(data["tree"])
        self._cpu = seen
        data["ui"] = self.own_name
        return data

    async def act(self, name: str, action: str, known: set[str]) -> str:
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; actions: {', '.join(ACTIONS)}")
        if name not in known:
            raise ValueError(f"no component {name!r}; components: {', '.join(sorted(known))}")
        if name == self.own_name and action != "restart":
            raise ValueError("the UI cannot stop itself from its own page")
        if action == "restart":
            if not self.supervisor_socket:
                raise ConnectionError("this UI runs without a supervisor")
            sup = AsyncRpcClient(self.supervisor_socket)
            try:  # wait=False: the UI may be restarting itself
                await sup.call(C.SUPERVISOR_LIFECYCLE, component=name, request="restart", by="ui", wait=False, timeout=10.0)
            finally:
                await sup.close()
            return "restarting; its supervisor starts a fresh process"
        client = AsyncRpcClient(self.control_socket(name))
        try:
            state = await client.call(C.GET_STATE, timeout=3.0)
            want = {"start": "activate", "stop": "deactivate"}[action]
            current = state.get("state")
            if (action == "start" and current == "active") or (action == "stop" and current != "active"):
                return f"already {current}"
            return str(await client.call(C.TRANSITION, timeout=10.0, transition=want))
        finally:
            await client.close()
