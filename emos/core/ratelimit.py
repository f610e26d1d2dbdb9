"""Rate-limited logging of repeated errors: the first occurrence in full, then counts.

A step that raises at 100 Hz must not write 100 tracebacks a second for the whole run. The
first occurrence of an error (same type, message and raising line) is logged with its
traceback; later identical ones are counted and reported as one line per ``window`` seconds.
"""
from __future__ import annotations

import logging
import time
from typing import Hashable


class RepeatLimiter:
    def __init__(self, window: float = 5.0, max_keys: int = 256):
        self.window = window
        self.max_keys = max_keys
        self._seen: dict[Hashable, list[float]] = {}  # key -> [window start, suppressed, total]

    def hit(self, key: Hashable, now: float | None = None) -> tuple[bool, bool, int]:
        """(log now?, first time ever?, how many were suppressed since the last log line)."""
        now = time.monotonic() if now is None else now
        entry = self._seen.get(key)
        if entry is None:
            if len(self._seen) >= self.max_keys:
                self._seen.clear()
            self._seen[key] = [now, 0, 1]
            return True, True, 0
        entry[2] += 1
        if now - entry[0] >= self.window:
            suppressed = int(entry[1])
            entry[0], entry[1] = now, 0
            return True, False, suppressed
        entry[1] += 1
        return False, False, 0

    def total(self, key: Hashable) -> int:
        entry = self._seen.get(key)
        return 0 if entry is None else int(entry[2])


def exception_key(exc: BaseException) -> tuple:
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = (tb.tb_frame.f_code.co_filename, tb.tb_lineno) if tb is not None else ("", 0)
    return (type(exc).__name__, str(exc)[:200], where)


def log_exception_limited(log: logging.Logger, limiter: RepeatLimiter, exc: BaseException, what: str) -> None:
    """Log ``exc`` raised by ``what`` in full the first time, then one counted line per window."""
    key = exception_key(exc)
    now_log, first, suppressed = limiter.hit(key)
    if not now_log:
        return
    if first:
        log.error("%s raised: %s", what, exc, exc_info=exc)
    else:
        log.error("%s raised %s: %s again (%d times in the last %.0f s, %d in all; traceback above)",
                  what, type(exc).__name__, exc, suppressed + 1, limiter.window, limiter.total(key))
