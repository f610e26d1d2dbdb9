"""Lowering a best-effort process's CPU priority, once, and only when it has a process of its own.

Best-effort parts of a run (the Monitor evaluating events, the web UI) read the same topics as
the robot's components; when the cores are short they should run second. ``os.nice`` on Linux
changes the calling thread (and the threads it starts later): in threaded mode that thread
would be the launcher's, so there it is left alone.
"""
from __future__ import annotations

import logging
import os
import threading

_lowered: set[int] = set()  # pids already lowered: a component re-activated in the same process is not lowered twice


def lower_priority(nice: int, who: str) -> bool:
    """Add ``nice`` (0-19) to this process's niceness; True if it did."""
    if not nice or threading.current_thread() is not threading.main_thread() or os.getpid() in _lowered:
        return False
    _lowered.add(os.getpid())
    try:
        os.nice(nice)
    except OSError as exc:
        logging.getLogger("emos.priority").warning("[%s] cannot lower its CPU priority by %d: %s", who, nice, exc)
        return False
    return True
