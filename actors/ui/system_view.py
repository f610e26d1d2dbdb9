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

    async def events(self, since: float = 0.0) -> list[dict[str, Any]]:
        """The supervisor's events (starts, exits, restarts, escalations) after ``since``."""
        if not self.supervisor_socket:
            raise ConnectionError("this UI runs without a supervisor")
        client = AsyncRpcClient(self.supervisor_socket)
        try:
            return list(await client.call(C.SUPERVISOR_EVENTS, timeout=3.0, since=since))
        finally:
            await client.close()

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


def describe_graph(components: list[Any], events_actions: list[Any]) -> dict[str, Any]:
    """The system graph the page draws and ``/api/v1/graph`` returns: components with the topics
    they publish and subscribe, topics with their types, and events (the topics they watch) with
    the actions they trigger (and the component an action acts on). Made in the launcher's
    process at bringup, from the recipe's own objects; plain JSON from then on."""
    topics: dict[str, dict[str, Any]] = {}

    def topic(t: Any) -> str:
        name = str(getattr(t, "name", t))
        msg_type = getattr(getattr(t, "msg_type", None), "__name__", None) or str(getattr(t, "msg_type", ""))
        topics.setdefault(name, {"name": name, "type": msg_type})
        return name

    comps = []
    for c in components:
        comps.append({"name": c.component_name, "type": type(c).__name__,
                      "publishes": sorted({topic(t) for t in getattr(c, "out_topics", None) or []}),
                      "subscribes": sorted({topic(t) for t in getattr(c, "in_topics", None) or []})})
    events = []
    for i, (event, actions) in enumerate(events_actions):
        try:
            watched = sorted(topic(t) for t in event.topics.values())
        except Exception:  # an event without topics (a timer): shown unconnected
            watched = []
        events.append({"name": getattr(event, "name", None) or f"event {i + 1}", "topics": watched,
                       "actions": [{"name": getattr(a, "method_name", type(a).__name__), "kind": getattr(a, "kind", "function"),
                                    "component": getattr(a, "component", None) if isinstance(getattr(a, "component", None), str)
                                    else getattr(getattr(a, "component", None), "component_name", None)} for a in actions]})
    return {"components": comps, "topics": sorted(topics.values(), key=lambda t: t["name"]), "events": events}
