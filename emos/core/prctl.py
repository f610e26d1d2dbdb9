"""Linux ``prctl`` for the process helpers every tier needs: parent-death signal, process name,
child subreaper.

It lives in core, not in the supervisor, because processes below the supervisor use it too (the
Zenoh status bridge asks to die with its supervisor; benchmark children die with the benchmark);
``emos.supervisor.spawn`` re-exports it for its zygote and workers.
"""
from __future__ import annotations

import ctypes
import os
import signal

PR_SET_NAME = 15
PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36

_libc: ctypes.CDLL | None
try:
    _libc = ctypes.CDLL(None, use_errno=True)
except OSError:  # pragma: no cover - non-glibc systems
    _libc = None


def prctl(option: int, arg: int | bytes) -> None:
    if _libc is None:
        raise OSError("prctl is not available on this platform")
    if _libc.prctl(option, arg if isinstance(arg, bytes) else ctypes.c_ulong(arg), 0, 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


def become_subreaper() -> None:
    prctl(PR_SET_CHILD_SUBREAPER, 1)


def set_process_name(name: str) -> None:
    """What ``ps``/``top`` show (15 bytes max): ``emos:<component>``."""
    try:
        prctl(PR_SET_NAME, name.encode()[:15])
    except OSError:
        pass


def die_with(parent_pid: int, sig: int = signal.SIGTERM) -> bool:
    """Ask for ``sig`` when ``parent_pid`` dies; False if it is already gone (or not our parent)."""
    prctl(PR_SET_PDEATHSIG, sig)
    return os.getppid() == parent_pid
