"""Observers: they watch the system under test and write what they see into the history.

* :class:`StatusObserver` polls the supervision tree (the same data as ``emos status``) and
  records every change of a component's pid, lifecycle state or health, and the launcher's
  zombie children. It also copies the supervisor's event log (the control socket's ``events``:
  exits, restarts, fallback attempts, give-ups) into the history as ``event`` records, on the
  history's clock (both are CLOCK_MONOTONIC), for checkers such as the fallback ladder's.
* :class:`TopicObserver` subscribes to topics from outside, like ``emos topic echo``, and
  records message arrivals. Messages stamped ``<seq>:<crc32>`` in ``header.frame_id`` (as the
  sensor demo and the chaos workloads stamp them) have their payload checksum verified, so a
  corrupt delivery is counted, never guessed. For velocity commands (``Twist``) it also keeps
  each command's size (``|vx| + |vy| + |omega|``), so checkers can tell a stopped robot from a
  moving one.
"""
from __future__ import annotations

import re
import threading
import time
import zlib
from collections import defaultdict
from typing import Any

import numpy as np

from emos.chaos.history import History
from emos.chaos.target import RunningSystem
from emos.core.discovery import worker_nodes
from emos.msgs.registry import resolve
from emos.transport.context import RunContext

_STAMP = re.compile(r"^(\d+):(\d+)$")


class StatusObserver(threading.Thread):
    def __init__(self, system: RunningSystem, history: History, interval: float = 0.02) -> None:
        super().__init__(name="chaos-status", daemon=True)
        self.system, self.history, self.interval = system, history, interval
        self.halt = threading.Event()
        self.max_zombies = 0
        self.errors = 0
        self._last: dict[str, tuple[Any, ...]] = {}
        self._zombies_before: set[int] = set()
        self._events_since = 0.0
        self._seen_events: set[tuple[Any, ...]] = set()

    def run(self) -> None:
        next_zombie_check = 0.0
        next_events = 0.0
        while not self.halt.is_set() and self.system.alive:
            if time.monotonic() >= next_events:
                self._copy_events()
                next_events = time.monotonic() + 0.5
            try:
                tree = self.system.tree(timeout=1.0)["tree"]
            except Exception:  # the supervisor may be busy restarting a group: count, keep going
                self.errors += 1
                self.halt.wait(self.interval)
                continue
            for w in worker_nodes(tree):
                key = (w.get("pid"), w.get("state"), w.get("health"), w.get("restarts", 0))
                if self._last.get(w["name"]) != key:
                    self._last[w["name"]] = key
                    self.history.add("status", w["name"], pid=key[0], state=key[1], health=key[2], restarts=key[3])
            zygotes = sorted(self.system.zygote_pids())
            if self._last.get("zygote") != tuple(zygotes):
                self._last["zygote"] = tuple(zygotes)
                self.history.add("status", "zygote", pids=zygotes)
            now = time.monotonic()
            if now >= next_zombie_check:
                zombies = self.system.zombie_pids()
                # Still a zombie a second later: nobody is reaping it (a transient one is a death
                # caught in the instant before the supervisor's reap).
                lasting = zombies & self._zombies_before
                self.max_zombies = max(self.max_zombies, len(lasting))
                if lasting:
                    self.history.add("note", "zombie", pids=sorted(lasting), parents=self.system.parents_of(lasting))
                self._zombies_before = zombies
                next_zombie_check = now + 1.0
            self.halt.wait(self.interval)


    def _copy_events(self) -> None:
        from emos.core.rpc import RpcClient

        try:
            with RpcClient(self.system.run_dir / "supervisor.sock", timeout=1.0) as rpc:  # type: ignore[operator]
                events = rpc.call("events", since=self._events_since)
        except Exception:  # busy or going down: the next poll gets them (``since`` is inclusive)
            self.errors += 1
            return
        for e in events:
            key = (e.get("t"), e.get("child"), e.get("event"))
            if key in self._seen_events:
                continue
            self._seen_events.add(key)
            self._events_since = max(self._events_since, float(e.get("t", 0.0)))
            detail = {k: v for k, v in e.items() if k not in ("t", "event")}
            self.history.records_event(float(e.get("t", 0.0)) - self.history.t0, str(e.get("event")), detail)

    def finish(self) -> None:
        """One last copy of the event log while the supervisor still answers."""
        self._copy_events()


class TopicObserver(threading.Thread):
    """Counts messages per topic and second, and checks stamped payloads."""

    def __init__(self, system: RunningSystem, history: History, topics: dict[str, str], interval: float = 0.005) -> None:
        super().__init__(name="chaos-topics", daemon=True)
        self.system, self.history, self.interval = system, history, interval
        self.types = {(t if t.startswith("/") else "/" + t): resolve(ty) for t, ty in topics.items()}
        self.halt = threading.Event()
        self.received: dict[str, int] = defaultdict(int)
        self.corrupt: dict[str, int] = defaultdict(int)
        self.errors: dict[str, int] = defaultdict(int)
        self.arrivals: dict[str, list[float]] = defaultdict(list)  # history times, for rates and recovery
        self.commands: dict[str, list[tuple[float, float]]] = defaultdict(list)  # (time, command size) of Twist topics

    def run(self) -> None:
        from emos.transport.pubsub import Subscriber

        assert self.system.run_id is not None and self.system.run_dir is not None
        ctx = RunContext(self.system.run_id, self.system.run_dir, owner=False)
        subs = {name: Subscriber(ctx, name, cls, queue_size=100) for name, cls in self.types.items()}
        last_rescan = 0.0
        try:
            while not self.halt.is_set() and self.system.alive:
                now = time.monotonic()
                for name, sub in subs.items():
                    try:
                        if now - last_rescan > 0.2:  # new rings appear when a publisher restarts
                            sub.rescan(force=True)
                        messages = sub.take()
                    except Exception as exc:  # a bad ring must not blind the observer: count it
                        self.errors[name] += 1
                        if self.errors[name] == 1:
                            self.history.add("note", name, error=f"{type(exc).__name__}: {exc}")
                        continue
                    for msg in messages:
                        self._check(name, msg)
                if now - last_rescan > 0.2:
                    last_rescan = now
                self.halt.wait(self.interval)
        finally:
            for sub in subs.values():
                sub.close()

    def _check(self, topic: str, msg: Any) -> None:
        self.received[topic] += 1
        now = self.history.now()
        self.arrivals[topic].append(now)
        linear, angular = getattr(msg, "linear", None), getattr(msg, "angular", None)
        if linear is not None and angular is not None:
            self.commands[topic].append((now, abs(linear.x) + abs(linear.y) + abs(angular.z)))
        header = getattr(msg, "header", None)
        match = _STAMP.match(getattr(header, "frame_id", "") or "")
        if match is None:
            return
        payload = next((getattr(msg, f) for f in ("data", "ranges") if getattr(msg, f, None) is not None), None)
        if payload is None:
            return
        crc = zlib.crc32(np.ascontiguousarray(payload).data) & 0xFFFFFFFF
        if crc != int(match.group(2)):
            self.corrupt[topic] += 1
            self.history.add("note", topic, corrupt=True, seq=int(match.group(1)))
