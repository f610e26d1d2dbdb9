"""Rate-limited logging: the one home for "say it once, then count the repeats".

A leaf module (standard library only) at the bottom of the package, so that every layer can
use it: ``emos.transport`` is imported by ``emos.core`` and cannot import ``emos.core`` back.

A problem that repeats (a step raising at 100 Hz, a forged ring seen at every rescan, a peer
sending garbage) must not flood the log, nor go unseen. :class:`RateLimitedLog` logs the first
occurrence of each key at once, in full (the caller names the component, topic or peer in the
message); later occurrences of that key within ``interval`` seconds are only counted, and the
next one after the interval is logged with how many were left out since the previous line::

    topic /scan: ignoring segment x: is owned by uid 1001
    topic /scan: ignoring segment x: is owned by uid 1001 (x37 in the last 10.0 s)

``x37`` counts the occurrences that were not logged between the two lines. Lines are written
only when an occurrence happens (no timer thread): a problem that stops is not reported again.
The clock is injectable, so tests count lines without waiting. Keys are bounded
(``max_keys``, least recently logged forgotten first) because peers can mint them (segment
names, topic names).
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Hashable
from typing import Any

__all__ = ["RateLimitedLog", "exception_key"]

_default_log = logging.getLogger("emos")


class RateLimitedLog:
    """Per-key rate-limited log lines (see the module docstring).

    ``logger``: where lines go (each call may override it with ``logger=``); ``interval`` (s):
    at most one line per key per interval; ``clock``: seconds, monotonic (``time.monotonic``
    unless a test passes its own); ``max_keys``: how many keys are remembered at most.
    """

    def __init__(self, logger: logging.Logger | None = None, interval: float = 10.0, *,
                 clock: Callable[[], float] = time.monotonic, max_keys: int = 4096) -> None:
        if not interval >= 0:
            raise ValueError(f"RateLimitedLog: interval must be a number of seconds >= 0, got {interval!r}")
        if not (isinstance(max_keys, int) and max_keys >= 1):
            raise ValueError(f"RateLimitedLog: max_keys must be an int >= 1, got {max_keys!r}")
        self.logger = logger if logger is not None else _default_log
        self.interval = float(interval)
        self.clock = clock
        self.max_keys = max_keys
        # key -> [last line at, occurrences left out since, occurrences in all]. Insertion order
        # is the order of the last line, so the first key is the one to forget.
        self._seen: dict[Hashable, list[Any]] = {}
        self._lock = threading.Lock()  # subscribers of several threads share one instance

    def admit(self, key: Hashable) -> tuple[bool, int, float]:
        """Count one occurrence of ``key``: (log it now?, occurrences left out since the previous
        line, seconds since that line; inf the first time)."""
        now = self.clock()
        with self._lock:
            entry = self._seen.get(key)
            if entry is None:
                if len(self._seen) >= self.max_keys:
                    del self._seen[next(iter(self._seen))]
                self._seen[key] = [now, 0, 1]
                return True, 0, float("inf")
            entry[2] += 1
            elapsed = now - entry[0]
            # A clock that went back (a restarted simulator, a test clock) starts a new interval.
            if elapsed < self.interval and elapsed >= 0:
                entry[1] += 1
                return False, 0, elapsed
            suppressed = entry[1]
            entry[0], entry[1] = now, 0
            del self._seen[key]  # move to the end: most recently logged
            self._seen[key] = entry
            return True, suppressed, elapsed

    def count(self, key: Hashable) -> int:
        """Occurrences of ``key`` seen in all (0 if unknown or forgotten)."""
        with self._lock:
            entry = self._seen.get(key)
            return 0 if entry is None else int(entry[2])

    def log(self, level: int, key: Hashable, msg: str, *args: object, logger: logging.Logger | None = None,
            exc_info: Any = None) -> bool:
        """Log ``msg % args`` at ``level`` unless ``key`` was logged less than ``interval`` ago;
        a line after left-out ones ends with ``(xN in the last T s)``. Returns whether it logged."""
        now_log, suppressed, elapsed = self.admit(key)
        if not now_log:
            return False
        if suppressed:
            msg = f"{msg} (x{suppressed} in the last {elapsed:.1f} s)"
        (logger or self.logger).log(level, msg, *args, exc_info=exc_info)
        return True

    def warning(self, key: Hashable, msg: str, *args: object, logger: logging.Logger | None = None) -> bool:
        return self.log(logging.WARNING, key, msg, *args, logger=logger)

    def error(self, key: Hashable, msg: str, *args: object, logger: logging.Logger | None = None) -> bool:
        return self.log(logging.ERROR, key, msg, *args, logger=logger)

    def exception(self, exc: BaseException, what: str, *, logger: logging.Logger | None = None) -> bool:
        """``exc`` raised by ``what`` (e.g. ``"[planner] execution step"``): the first time with
        its traceback, then one counted line per interval pointing back at it. Exceptions of the
        same type and message raised at the same line share a key."""
        key = exception_key(exc)
        now_log, suppressed, elapsed = self.admit(key)
        if not now_log:
            return False
        out = logger or self.logger
        total = self.count(key)
        if total <= 1:
            out.error("%s raised: %s", what, exc, exc_info=exc)
        else:
            counts = f"x{suppressed} in the last {elapsed:.1f} s, " if suppressed else ""
            out.error("%s raised %s: %s again (%s%d in all; traceback above)", what, type(exc).__name__, exc, counts, total)
        return True


def exception_key(exc: BaseException) -> tuple[str, str, tuple[str, int]]:
    """(type name, message, (file, line) where it was raised): what makes two errors "the same"."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = (tb.tb_frame.f_code.co_filename, tb.tb_lineno) if tb is not None else ("", 0)
    return (type(exc).__name__, str(exc)[:200], where)
