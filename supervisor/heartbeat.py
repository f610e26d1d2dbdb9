"""Hang detection: every component's ``<name>/status`` stream is its heartbeat."""
from __future__ import annotations

import asyncio
import time
from typing import Any

from emos.msgs.status import ComponentStatus
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker


class HeartbeatMonitor:
    """Calls ``worker.on_hang(silent_for)`` when a watched component is silent past ``timeout``."""

    def __init__(self, ctx: RunContext, timeout: float, check_period: float | None = None):
        if timeout <= 0:
            raise ValueError(f"heartbeat timeout must be > 0 s, got {timeout}")
        self.ctx = ctx
        self.timeout = timeout
        self.check_period = check_period or min(0.05, timeout / 4)
        self.loop = asyncio.get_running_loop()
        self.waker = Waker(ctx)
        self.loop.add_reader(self.waker.fd, self._on_wake)
        self.subs: dict[str, Subscriber] = {}
        self.watched: dict[str, tuple[Any, float]] = {}  # name -> (worker, last heard, monotonic)
        self.status: dict[str, ComponentStatus] = {}
        self._task = asyncio.ensure_future(self._check_loop())

    def watch(self, name: str, worker: Any) -> None:
        if name not in self.subs:
            self.subs[name] = Subscriber(self.ctx, f"/{name}/status", ComponentStatus, waker=self.waker, queue_size=4)
        self.watched[name] = (worker, time.monotonic())
        self._on_wake()

    def unwatch(self, name: str, worker: Any) -> None:
        current = self.watched.get(name)
        if current is not None and current[0] is worker:
            del self.watched[name]

    def last_status(self, name: str) -> ComponentStatus | None:
        self._on_wake()
        return self.status.get(name)

    def _on_wake(self) -> None:
        self.waker.drain()
        now = time.monotonic()
        for name, sub in self.subs.items():
            # take() goes through the subscriber's validated path: a damaged or forged ring, or
            # a frame that does not decode, is dropped and logged there and cannot raise here.
            items = sub.take()
            if not items:
                continue
            self.status[name] = items[-1]
            if name in self.watched:
                self.watched[name] = (self.watched[name][0], now)

    async def _check_loop(self) -> None:
        while True:
            await asyncio.sleep(self.check_period)
            self._on_wake()  # in case a wake-up was lost to a full FIFO
            now = time.monotonic()
            for name, (worker, last) in list(self.watched.items()):
                if now - last > self.timeout:
                    del self.watched[name]
                    worker.on_hang(now - last)

    def close(self) -> None:
        self._task.cancel()
        self.loop.remove_reader(self.waker.fd)
        for sub in self.subs.values():
            sub.close()
        self.waker.close()
