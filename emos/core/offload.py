"""Blocking work off a component's event loop: one worker thread with a bounded backlog.

A component step runs on the node's event loop, which also publishes the status heartbeat. A
step that waits for a model server (or runs a detector for 100 ms) would silence the heartbeat
and get the component killed as hung. Such steps hand the blocking part to a ``StepWorker``:
the loop returns at once, the worker runs jobs one at a time, in order.

The backlog is bounded and says what happens when it is full: ``latest`` keeps only the newest
job (a camera frame older than the one just received is worth nothing; the replaced jobs are
counted as dropped), ``queue`` keeps up to ``max_pending`` jobs and drops the oldest beyond
that (a user's questions should all be answered, but not hours late).

Jobs submitted as *steps* (``submit(job, step=True)``: the component's work on a trigger, not
its housekeeping such as reconnecting to a model server) are counted, so a lockstep clock can
wait for the steps of a tick (``wait_steps``) and charge the CPU they took (``take_cpu``):
see ``emos.core.clock.SimTimeDriver.hold_ticks_for``.
"""
from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

POLICIES = ("latest", "queue")


class StepWorker:
    def __init__(self, name: str, policy: str = "queue", max_pending: int = 16,
                 on_error: Callable[[BaseException], None] | None = None) -> None:
        if policy not in POLICIES:
            raise ValueError(f"StepWorker {name!r}: policy must be one of {POLICIES}, got {policy!r}")
        if isinstance(max_pending, bool) or not isinstance(max_pending, int) or max_pending < 1:
            raise ValueError(f"StepWorker {name!r}: max_pending must be an integer >= 1, got {max_pending!r}")
        self.name = name
        self.policy = policy
        self.max_pending = 1 if policy == "latest" else max_pending
        self.on_error = on_error
        self.dropped = 0
        self.done = 0
        self._jobs: collections.deque[tuple[Callable[[], Any], bool]] = collections.deque()  # (job, is a step)
        self._cond = threading.Condition()
        self._busy = False
        self._steps = 0  # step jobs waiting or running
        self._cpu_s = 0.0  # thread CPU seconds of the jobs run since the last take_cpu()
        self._stopping = False
        self._thread: threading.Thread | None = None
        self._log = logging.getLogger(f"emos.{name}.worker")

    # ------------------------------------------------------------------ control
    def start(self) -> None:
        with self._cond:
            if self._thread is not None and self._thread.is_alive():
                return
            self._stopping = False
            self._thread = threading.Thread(target=self._run, name=f"{self.name}-worker", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 5.0) -> bool:
        """Drop queued jobs, let the running one finish (up to ``timeout``); True if it did."""
        with self._cond:
            self._stopping = True
            self._drop_waiting(count=False)
            self._cond.notify_all()
            thread = self._thread
        if thread is None:
            return True
        thread.join(timeout)
        alive = thread.is_alive()
        if alive:
            self._log.warning("[%s] a job is still running %.1f s after stop; leaving it behind", self.name, timeout)
        self._thread = None
        return not alive

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def busy(self) -> bool:
        """A job is running or waiting."""
        with self._cond:
            return self._busy or bool(self._jobs)

    @property
    def pending(self) -> int:
        with self._cond:
            return len(self._jobs)

    # ------------------------------------------------------------------ jobs
    def submit(self, job: Callable[[], Any], step: bool = False) -> bool:
        """Queue ``job`` (``step``: the component's work on a trigger, see the module's doc);
        False if the worker is not running (the job is not kept)."""
        with self._cond:
            if self._thread is None or self._stopping:
                return False
            while len(self._jobs) >= self.max_pending:
                _, was_step = self._jobs.popleft()
                self._steps -= was_step
                self.dropped += 1
            self._jobs.append((job, step))
            self._steps += step
            self._cond.notify()
        return True

    def clear(self) -> int:
        """Drop every waiting job (counted as dropped); the running one goes on."""
        with self._cond:
            return self._drop_waiting(count=True)

    def _drop_waiting(self, count: bool) -> int:
        n = len(self._jobs)
        self._steps -= sum(step for _, step in self._jobs)
        self._jobs.clear()
        if count:
            self.dropped += n
        self._cond.notify_all()
        return n

    def wait_idle(self, timeout: float) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: not self._busy and not self._jobs, timeout)

    def wait_steps(self, timeout: float) -> bool:
        """Wait (up to ``timeout`` wall seconds) until no step job is waiting or running; True if none is."""
        with self._cond:
            return self._cond.wait_for(lambda: self._steps == 0, timeout)

    def take_cpu(self) -> float:
        """Thread CPU seconds of the jobs finished since the last call."""
        with self._cond:
            cpu, self._cpu_s = self._cpu_s, 0.0
            return cpu

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._jobs or self._stopping)
                if self._stopping:
                    self._busy = False
                    self._cond.notify_all()
                    return
                job, step = self._jobs.popleft()
                self._busy = True
            cpu0 = time.thread_time()
            try:
                job()
            except BaseException as exc:  # a job must never kill the worker
                if self.on_error is not None:
                    try:
                        self.on_error(exc)
                    except Exception:
                        self._log.exception("[%s] error handler raised", self.name)
                else:
                    self._log.exception("[%s] job raised: %s", self.name, exc)
            finally:
                with self._cond:
                    self._busy = False
                    self._steps -= step
                    self._cpu_s += time.thread_time() - cpu0
                    self.done += 1
                    self._cond.notify_all()
