"""Retry with exponential backoff: one policy, run by :func:`retry` (blocking) or
:func:`retry_async` (in an event loop).

    retry(lambda: client.call("get_state"), Backoff(base=0.01, cap=0.2, timeout=10.0),
          retry_on=RpcConnectionError)

After the n-th failure the runner waits ``base * factor ** (n - 1)`` seconds (at most ``cap``),
then calls again. It gives up, raising the last exception unchanged (the caller words the final
error: it knows what was being reached), when

* the exception is not one of ``retry_on``, or ``retry_if(exc)`` says it is not worth retrying;
* ``attempts`` calls have failed;
* ``timeout`` seconds have passed since the first call. The last wait is cut to end at the
  deadline, where one last call is made, so "unreachable for ``timeout`` s" means that long.

``sleep`` and ``clock`` are injectable: a test passes a fake pair and checks the delays that were
asked for, without waiting.
"""
from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import attrs

from emos.config import validators as V

T = TypeVar("T")
ExceptionTypes = type[BaseException] | tuple[type[BaseException], ...]


@attrs.frozen
class Backoff:
    """How often and how patiently to retry. ``attempts``: calls in all (None: as many as
    ``timeout`` allows); ``timeout``: seconds from the first call (None: as many as ``attempts``)."""

    attempts: int | None = attrs.field(default=None, validator=V.number(ge=1, integer=True, allow_none=True))
    base: float = attrs.field(default=0.1, validator=V.number(ge=0))
    factor: float = attrs.field(default=2.0, validator=V.number(ge=0))
    cap: float | None = attrs.field(default=None, validator=V.number(ge=0, allow_none=True))
    timeout: float | None = attrs.field(default=None, validator=V.number(ge=0, allow_none=True))

    def __attrs_post_init__(self) -> None:
        if self.attempts is None and self.timeout is None:
            raise ValueError("Backoff: give attempts or timeout (or both); with neither it would retry forever")

    def delay(self, failures: int) -> float:
        """Seconds to wait after the ``failures``-th failure (from 1)."""
        delay = self.base * self.factor ** (failures - 1)
        return delay if self.cap is None else min(delay, self.cap)


class _Run:
    """The bookkeeping shared by the two runners."""

    def __init__(self, policy: Backoff, retry_on: ExceptionTypes, retry_if: Callable[[BaseException], bool] | None,
                 on_retry: Callable[[BaseException, int, float], None] | None, clock: Callable[[], float]):
        self.policy, self.retry_on, self.retry_if, self.on_retry, self.clock = policy, retry_on, retry_if, on_retry, clock
        self.deadline = None if policy.timeout is None else clock() + policy.timeout
        self.failures = 0

    def wait_after(self, exc: BaseException) -> float | None:
        """Seconds to wait before the next call, or None: give up (the caller raises ``exc``)."""
        if not isinstance(exc, self.retry_on) or (self.retry_if is not None and not self.retry_if(exc)):
            return None
        self.failures += 1
        policy = self.policy
        if policy.attempts is not None and self.failures >= policy.attempts:
            return None
        delay = policy.delay(self.failures)
        if self.deadline is not None:
            left = self.deadline - self.clock()
            if left <= 0:
                return None
            delay = min(delay, left)
        if self.on_retry is not None:
            self.on_retry(exc, self.failures, delay)
        return delay


def retry(call: Callable[[], T], policy: Backoff, *, retry_on: ExceptionTypes = Exception,
          retry_if: Callable[[BaseException], bool] | None = None,
          on_retry: Callable[[BaseException, int, float], None] | None = None,
          sleep: Callable[[float], Any] | None = None, clock: Callable[[], float] | None = None) -> T:
    """``call()``, retried as ``policy`` says. ``on_retry(exc, failures, delay)`` runs before each
    wait (to log it). ``sleep``, ``clock``: default ``time.sleep`` and ``time.monotonic``, looked
    up at each call (so a test may patch them)."""
    sleep = time.sleep if sleep is None else sleep
    run = _Run(policy, retry_on, retry_if, on_retry, time.monotonic if clock is None else clock)
    while True:
        try:
            return call()
        except BaseException as exc:
            delay = run.wait_after(exc)
            if delay is None:
                raise
        sleep(delay)


async def retry_async(call: Callable[[], Awaitable[T]], policy: Backoff, *, retry_on: ExceptionTypes = Exception,
                      retry_if: Callable[[BaseException], bool] | None = None,
                      on_retry: Callable[[BaseException, int, float], None] | None = None,
                      sleep: Callable[[float], Awaitable[Any]] | None = None,
                      clock: Callable[[], float] | None = None) -> T:
    """``await call()``, retried as ``policy`` says (waits with ``await sleep(delay)``; default
    ``asyncio.sleep``)."""
    asleep = asyncio.sleep if sleep is None else sleep
    run = _Run(policy, retry_on, retry_if, on_retry, time.monotonic if clock is None else clock)
    while True:
        try:
            return await call()
        except BaseException as exc:
            delay = run.wait_after(exc)
            if delay is None:
                raise
        await asleep(delay)


__all__ = ["Backoff", "retry", "retry_async"]
