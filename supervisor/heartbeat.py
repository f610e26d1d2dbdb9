"""Hang detection: every component's ``<name>/status`` stream is its heartbeat.

Only the component's own process counts. Anyone in the run may publish on ``/<name>/status``
(``emos topic pub`` does), and a status from elsewhere must not keep a hung component alive.
So the monitor reads only the ring whose publisher id is the component's name, and only while
that ring's writer pid is the pid of the incarnation it watches (a process that opens the same
ring to forge beats takes the writer pid, and the real component then looks silent: a false
restart, never a masked hang). The ring is the cheapest channel that proves liveness where it
matters: it is written by the component's event loop after every step, at no extra cost; a
beat over the control socket would add a system call per beat for the same proof.
"""
from __future__ import annotations

import asyncio
import logging
import time
from typing import Any

from emos.msgs import codec
from emos.msgs.status import ComponentStatus
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker

log = logging.getLogger("emos.supervisor")

FOREIGN_LOG_PERIOD_S = 10.0  # one warning per component per period about foreign status publishers


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
        self.pids: dict[str, int] = {}  # name -> pid whose beats count
        self.status: dict[str, ComponentStatus] = {}
        self.foreign: dict[str, int] = {}  # name -> status messages ignored (not from the component)
        self._foreign_logged: dict[str, float] = {}
        self._task = asyncio.ensure_future(self._check_loop())

    def expect(self, name: str, pid: int | None) -> None:
        """A new incarnation of ``name`` runs as ``pid`` and is starting: its status is its own
        from now on. It publishes from configure on, before it is watched; without this, every
        restart logged the new process's first beats as a foreign publisher's (the monitor
        still held the dead incarnation's pid)."""
        self._subscribe(name)
        self.pids[name] = int(pid or 0)

    def watch(self, name: str, worker: Any) -> None:
        self._subscribe(name)
        self.pids[name] = int(worker.pid or 0)
        self.watched[name] = (worker, time.monotonic())
        self._on_wake()

    def _subscribe(self, name: str) -> None:
        if name not in self.subs:
            self.subs[name] = Subscriber(self.ctx, f"/{name}/status", ComponentStatus, waker=self.waker, queue_size=4)

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
            self._note_foreign(name, sub)
            # take_raw_from reads through the subscriber's validated path: a damaged or forged
            # ring is dropped and logged there and cannot raise here.
            items, writer_pid = sub.take_raw_from(name)
            if not items:
                continue
            if writer_pid != self.pids.get(name):
                # Counted (and said) only against a watched incarnation: while none is (between a
                # death and the next start), what is left of the dead one's beats is just dropped.
                if name in self.watched:
                    self._count_foreign(name, len(items), f"ring of {name!r} written by pid {writer_pid}, not by the component's pid {self.pids.get(name)}")
                continue
            try:
                self.status[name] = codec.decode(ComponentStatus, items[-1][1])
            except codec.DecodeError as exc:  # a bad frame must not kill the heartbeat task
                self._count_foreign(name, 1, f"an undecodable status frame ({type(exc).__name__}: {exc})")
            if name in self.watched:
                self.watched[name] = (self.watched[name][0], now)

    def _note_foreign(self, name: str, sub: Subscriber) -> None:
        others = [p for p in sub.sources if p != name]
        if others:
            self._count_foreign(name, 0, f"publisher(s) {', '.join(sorted(others))}")

    def _count_foreign(self, name: str, count: int, who: str) -> None:
        self.foreign[name] = self.foreign.get(name, 0) + count
        now = time.monotonic()
        if now - self._foreign_logged.get(name, -FOREIGN_LOG_PERIOD_S) >= FOREIGN_LOG_PERIOD_S:
            self._foreign_logged[name] = now
            log.warning("[%s] status from %s does not count as its heartbeat: only the component's own process does", name, who)

    async def _check_loop(self) -> None:
        failures, logged_at = 0, float("-inf")
        while True:
            await asyncio.sleep(self.check_period)
            try:
                self._on_wake()  # in case a wake-up was lost to a full FIFO
                now = time.monotonic()
                for name, (worker, last) in list(self.watched.items()):
                    if now - last > self.timeout:
                        del self.watched[name]
                        worker.on_hang(now - last)
            except Exception:  # noqa: BLE001 - hang detection must outlive any one bad tick
                failures += 1
                if time.monotonic() - logged_at >= FOREIGN_LOG_PERIOD_S:
                    logged_at = time.monotonic()
                    log.exception("heartbeat check failed (%d time(s) so far); hang detection carries on", failures)

    def close(self) -> None:
        self._task.cancel()
        self.loop.remove_reader(self.waker.fd)
        for sub in self.subs.values():
            sub.close()
        self.waker.close()
