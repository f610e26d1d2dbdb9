"""Simulation time: one clock per World, readable by any thread.

Three modes:

- ``realtime``: each tick sleeps so that simulated time follows wall time, optionally scaled by
  ``real_time_factor`` (2.0 runs twice as fast as the wall clock). The default, as users of a
  simulator expect to watch a robot move at its real speed.
- ``fast``: no pacing; the world steps as fast as the machine allows.
- ``lockstep``: no pacing and no background stepping; time advances only when the caller
  calls ``World.step()``. Benchmarks and tests use it so results do not depend on load.

Other code reads ``now()`` and waits with ``sleep_until()`` / ``rate(hz).sleep()``, which wait
on *simulated* time, so a controller written against the clock behaves the same in all modes.
"""
from __future__ import annotations

import enum
import threading
import time

import attrs

from emos.config import validators as V


class ClockMode(str, enum.Enum):
    REALTIME = "realtime"
    FAST = "fast"
    LOCKSTEP = "lockstep"


@attrs.define(eq=False)
class SimClock:
    """Simulated time advanced in fixed ticks of ``dt`` seconds."""

    dt: float = attrs.field(default=0.01, converter=float, validator=V.positive)
    mode: ClockMode = attrs.field(default=ClockMode.REALTIME, converter=ClockMode)
    real_time_factor: float = attrs.field(default=1.0, converter=float, validator=V.positive)
    _ticks: int = attrs.field(default=0, init=False)
    _wall_start: float | None = attrs.field(default=None, init=False)
    _cond: threading.Condition = attrs.field(factory=threading.Condition, init=False)

    @property
    def ticks(self) -> int:
        return self._ticks

    def now(self) -> float:
        """Simulated seconds since the world started (exact multiple of dt)."""
        return self._ticks * self.dt

    def now_ns(self) -> int:
        return int(round(self._ticks * self.dt * 1e9))

    def stamp(self) -> tuple[int, int]:
        """(sec, nanosec) of now(), the ROS ``builtin_interfaces/Time`` split."""
        ns = self.now_ns()
        return ns // 1_000_000_000, ns % 1_000_000_000

    def tick(self) -> float:
        """Advance one tick, pace it if the mode asks for it, wake waiters; return now()."""
        if self.mode is ClockMode.REALTIME:
            if self._wall_start is None:
                self._wall_start = time.monotonic()
            # Pace against the start time, not the previous tick, so sleep jitter never
            # accumulates into drift.
            target = self._wall_start + (self._ticks + 1) * self.dt / self.real_time_factor
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        with self._cond:
            self._ticks += 1
            self._cond.notify_all()
        return self.now()

    def sleep_until(self, t: float, timeout: float | None = None) -> bool:
        """Block until simulated time reaches ``t``; False if the wall ``timeout`` ran out."""
        with self._cond:
            return self._cond.wait_for(lambda: self.now() >= t - 1e-12, timeout=timeout)

    def sleep(self, duration: float, timeout: float | None = None) -> bool:
        return self.sleep_until(self.now() + duration, timeout=timeout)

    def rate(self, hz: float) -> SimRate:
        return SimRate(self, hz)

    def reset(self) -> None:
        with self._cond:
            self._ticks = 0
            self._wall_start = None
            self._cond.notify_all()


class SimRate:
    """Like ``rospy.Rate`` on simulated time: ``sleep()`` waits for the next period boundary."""

    def __init__(self, clock: SimClock, hz: float) -> None:
        if not hz > 0:
            raise ValueError(f"SimRate hz must be > 0, got {hz!r}")
        self._clock = clock
        self.period = 1.0 / hz
        self._next = clock.now() + self.period

    def sleep(self, timeout: float | None = None) -> bool:
        ok = self._clock.sleep_until(self._next, timeout=timeout)
        now = self._clock.now()
        # Skip missed periods rather than bursting to catch up.
        while self._next <= now + 1e-12:
            self._next += self.period
        return ok
