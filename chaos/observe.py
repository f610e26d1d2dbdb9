"""Observers: they watch the system under test and write what they see into the history.

* :class:`StatusObserver` polls the supervision tree (the same data as ``emos status``) and
  records every change of a component's pid, lifecycle state or health, and the launcher's
  zombie children.
* :class:`TopicObserver` subscribes to topics from outside, like ``emos topic echo``, and
  records message arrivals. Messages stamped ``<seq>:<crc32>`` in ``header.frame_id`` (as the
  sensor demo and the chaos workloads stamp them) have their payload checksum verified, so a
  corrupt delivery is counted, never guessed.
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
from emos.chaos.target import RunningSystem, iter_workers
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

    def run(self) -> None:
        next_zombie_check = 0.0
        while not self.halt.is_set() and self.system.alive:
            try:
                tree = self.system.tree(timeout=1.0)["tree"]
            except Exception:  # the supervisor may be busy restarting a group: count, keep going
                self.errors += 1
                self.halt.wait(self.interval)
                continue
            for w in iter_workers(tree):
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
                self.max_zombies = max(self.max_zombies, len(zombies & self._zombies_before))
                self._zombies_before = zombies
                next_zombie_check = now + 1.0
            self.halt.wait(self.interval)


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
        self.arrivals[topic].append(self.history.now())
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
