"""The UI's access token in a file only its user can read, while the UI listens.

Scripts and a user who lost the printed link read it there (as with Jupyter's runtime files).
The file lives in the run's directory (``<runtime dir>/<run id>/ui.token``), which only we can
enter; the directory is checked anyway, since a token written where another user can list or
replace files would be theirs too.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from emos.errors import EmosError
from emos.transport.trust import remove_owned

FILE_MODE = 0o600


class TokenFileRefused(EmosError, PermissionError):
    """The token file cannot be written safely (the path and the reason are in the message)."""


def _directory_problem(directory: Path) -> str | None:
    try:
        st = os.lstat(directory)
    except FileNotFoundError:
        return "does not exist"
    if stat.S_ISLNK(st.st_mode):
        return "is a symbolic link"
    if not stat.S_ISDIR(st.st_mode):
        return "is not a directory"
    if st.st_uid != os.geteuid():
        return f"is owned by uid {st.st_uid}, not by us (uid {os.geteuid()})"
    if stat.S_IMODE(st.st_mode) & 0o077:
        return f"has mode {oct(stat.S_IMODE(st.st_mode))}, not 0o700"
    return None


def write_token_file(path: Path, token: str) -> None:
    """Write ``token`` to ``path`` with mode 0600, atomically; the directory must be ours, 0700."""
    write_private_file(path, token + "\n", "the UI's access token")


def write_private_file(path: Path, text: str, what: str = "a private file of the UI") -> None:
    """Write ``text`` to ``path`` with mode 0600, atomically; the directory must be ours, 0700.
    ``what`` names the content in the refusal (the device-token store, the pairing code)."""
    path = Path(path)
    problem = _directory_problem(path.parent)
    if problem is not None:
        raise TokenFileRefused(f"not writing {what} to {path}: the directory {path.parent} {problem} "
                               "(it must be a directory of ours with mode 0700)")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    remove_owned(tmp, mode=None)  # left by a process of ours killed mid-write
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, FILE_MODE)
    try:
        os.fchmod(fd, FILE_MODE)  # exactly 0600, whatever the umask
        os.write(fd, text.encode())
    finally:
        os.close(fd)
    os.replace(tmp, path)


def directory_problem(directory: Path) -> str | None:
    """Why ``directory`` is no place for a secret of ours (``None``: it is ours, 0700)."""
    return _directory_problem(Path(directory))


def remove_token_file(path: Path) -> str | None:
    """Remove the token file if it is ours; returns why it was left in place, or ``None``."""
    return remove_owned(Path(path), mode=FILE_MODE)
