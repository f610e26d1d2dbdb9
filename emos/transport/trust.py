"""Opening and removing files that other local users may have planted.

``/dev/shm`` and ``/tmp`` are shared by every user of the machine, and a run's id is visible to
all of them (``ps``, ``ls /dev/shm``). So a name in the run's namespace proves nothing: another
user may have created it first, as a forged ring, a directory, a symbolic link, or a file of
their own. Every segment this package opens or removes goes through here, and is used only if
it is a regular file, owned by our effective uid, with exactly the mode we create segments with.
Whatever fails the check is skipped and reported (rate-limited), never followed and never
allowed to raise out of a subscriber, the supervisor or a clean-up.
"""
from __future__ import annotations

import errno
import logging
import os
import stat
from pathlib import Path

from emos.errors import TransportError
from emos.ratelimit import RateLimitedLog

__all__ = ["SEGMENT_MODE", "UntrustedFile", "check_path", "distrust_reason", "open_owned", "rate_limited", "remove_owned"]

log = logging.getLogger("emos.transport")

SEGMENT_MODE = 0o600


class UntrustedFile(TransportError, OSError):
    """A file in a shared directory that is not ours to use (its path and why are in the message)."""


def distrust_reason(st: os.stat_result, mode: int = SEGMENT_MODE) -> str | None:
    """Why a file with status ``st`` (from ``lstat``/``fstat``) must not be used, or ``None``."""
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "a symbolic link" if stat.S_ISLNK(st.st_mode) else "not a regular file"
        return f"is {kind}"
    if st.st_uid != os.geteuid():
        return f"is owned by uid {st.st_uid}, not by us (uid {os.geteuid()})"
    if stat.S_IMODE(st.st_mode) != mode:
        return f"has mode {oct(stat.S_IMODE(st.st_mode))}, not {oct(mode)}"
    return None


def check_path(path: Path, mode: int = SEGMENT_MODE) -> str | None:
    """:func:`distrust_reason` of ``path`` without following a link; ``"vanished"`` if it is gone."""
    try:
        return distrust_reason(os.lstat(path), mode)
    except FileNotFoundError:
        return "vanished"


def open_owned(path: Path, mode: int = SEGMENT_MODE) -> int:
    """Open an existing file read-write only if it is ours (see module doc); returns the fd.

    Raises ``FileNotFoundError`` if it does not exist and :class:`UntrustedFile` if it is not ours.
    The check is made on the opened descriptor, so the file cannot be swapped after the check.
    """
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise UntrustedFile(f"{path} is a symbolic link") from None
        raise UntrustedFile(f"{path} cannot be opened: {exc.strerror}") from None
    try:
        reason = distrust_reason(os.fstat(fd), mode)
    except OSError:
        os.close(fd)
        raise
    if reason is not None:
        os.close(fd)
        raise UntrustedFile(f"{path} {reason}")
    return fd


def remove_owned(path: Path, mode: int | None = SEGMENT_MODE) -> str | None:
    """Unlink ``path`` if it is a regular file of ours; otherwise leave it and say why.

    ``mode=None`` accepts any mode (files we own but whose mode we did not set ourselves).
    Returns ``None`` when removed (or already gone), else the reason it was left in place.
    """
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    reason = distrust_reason(st, stat.S_IMODE(st.st_mode) if mode is None else mode)
    if reason is not None:
        return reason
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError as exc:
        return f"cannot be removed: {exc.strerror}"
    return None


# The transport's shared instance (segments, wake-up files, clean-up), keyed by what it names.
rate_limited = RateLimitedLog(log, interval=10.0)
