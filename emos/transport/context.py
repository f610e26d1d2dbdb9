"""Where a running system keeps its shared state, and how stale state of dead runs is swept.

A *run* is one supervised system (or one stand-alone process using topics). It owns:

- shared-memory segments ``/dev/shm/emos.<run_id>.<...>`` (mode 0600), one per ring;
- a private directory ``<runtime>/emos-<uid>/<run_id>/`` (mode 0700) holding Unix sockets,
  wake-up FIFOs and per-topic subscriber lists.

``run_id`` is ``<owner pid>-<owner start time>``: a later run can tell a dead owner from a live
one even if the pid was reused, and removes what the dead one left behind.

Both directories are shared with every other user, who can see run ids and plant names in
advance. So clean-up touches only regular files of our own uid and reports (never follows,
never trips over) anything else; the runtime root must be a real directory of ours, mode 0700.
"""
from __future__ import annotations

import atexit
import logging
import os
import re
import shutil
import stat
import threading
from collections.abc import Iterator
from pathlib import Path

import psutil

from emos.errors import TransportError
from emos.transport.trust import rate_limited, remove_owned

log = logging.getLogger("emos.transport")

SHM_DIR = Path("/dev/shm")
SHM_PREFIX = "emos."
ENV_RUN_DIR = "EMOS_RUN_DIR"
ENV_RUN_ID = "EMOS_RUN_ID"
ENV_RUNTIME_DIR = "EMOS_RUNTIME_DIR"  # overrides where run directories live
TMP_DIR = Path("/tmp")
_RUN_ID_RE = re.compile(r"^(\d+)-(\d+)$")


class RuntimeDirError(TransportError, PermissionError):
    """The directory for run directories cannot be used safely (another user owns or opened it)."""


def runtime_root() -> Path:
    """Where run directories live: ``$EMOS_RUNTIME_DIR`` if set, else ``$XDG_RUNTIME_DIR/emos``
    when that exists (a per-user tmpfs), else ``/tmp/emos-<euid>``.

    The directory must be a real directory (not a link) owned by us with mode 0700: another
    user must not be able to plant sockets or FIFOs where we will connect. In ``/tmp`` anyone
    can create ``emos-<uid>`` first; then we refuse, naming the owner and the way out, rather
    than run in (or delete) a directory someone else controls.

    Owning the directory is not enough: whoever owns a directory above it can rename it away
    mid-run and put another in its place. ``sudo -E`` and ``su`` leave ``XDG_RUNTIME_DIR``
    pointing at the invoking user's ``/run/user/<uid>``, so every directory on the way must be
    ours or root's, and one that others may write must be sticky (as ``/tmp`` is).
    """
    uid = os.geteuid()
    explicit = os.environ.get(ENV_RUNTIME_DIR)
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    source: str | None = None  # the variable that chose the directory, named in a refusal
    if explicit:
        root, source = Path(explicit), ENV_RUNTIME_DIR
    elif xdg and Path(xdg).is_dir():
        root, source = Path(xdg) / "emos", "XDG_RUNTIME_DIR"
    else:
        root = TMP_DIR / f"emos-{uid}"
    _check_ancestors(root, uid, source)
    try:
        root.mkdir(mode=0o700, parents=True, exist_ok=True)
    except FileExistsError:
        pass  # a file or a dangling link: reported below
    st = os.lstat(root)
    problem = None
    if not stat.S_ISDIR(st.st_mode):
        problem = "is not a directory" if not stat.S_ISLNK(st.st_mode) else "is a symbolic link"
    elif st.st_uid != uid:
        problem = f"is owned by uid {st.st_uid}, not by us (uid {uid})"
    elif stat.S_IMODE(st.st_mode) != 0o700:
        problem = f"has mode {oct(stat.S_IMODE(st.st_mode))}, not 0o700"
    if problem is not None:
        raise RuntimeDirError(
            f"the EMOS runtime directory {root} {problem}; another user may have created it to "
            f"interfere with our runs. Remove it, or set {ENV_RUNTIME_DIR} to a directory of "
            f"yours with mode 0700 (it is created if missing)"
        )
    return root


def _unsafe_directory(path: Path, uid: int) -> str | None:
    """Why another user could replace what lies under ``path``, or None if nobody but us (and
    root) can."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None  # created below by mkdir, under a parent that passed this check
    if st.st_uid not in (uid, 0):
        return f"is owned by uid {st.st_uid}, not by us (uid {uid}) or root"
    if stat.S_ISLNK(st.st_mode):
        return None  # a link's own mode means nothing; its target is checked on the resolved path
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH) and not st.st_mode & stat.S_ISVTX:
        return f"is writable by other users (mode {oct(stat.S_IMODE(st.st_mode))}) without the sticky bit"
    return None


def _check_ancestors(root: Path, uid: int, variable: str | None) -> None:
    """Refuse a runtime directory whose parents another user controls (see runtime_root)."""
    absolute = Path(os.path.abspath(root))
    # The path as written (a planted link is refused by its owner) and as resolved (a link of
    # root's to a directory someone else owns is refused by the target's owner).
    for chain in (absolute.parents, Path(os.path.realpath(absolute.parent)).joinpath("x").parents):
        for parent in chain:
            problem = _unsafe_directory(parent, uid)
            if problem is None:
                continue
            via = f" (from {variable}={os.environ.get(variable)})" if variable else ""
            hint = ("unset XDG_RUNTIME_DIR (`sudo -E` and `su` leave the invoking user's there) or set "
                    f"{ENV_RUNTIME_DIR} to a directory of yours") if variable == "XDG_RUNTIME_DIR" else \
                f"set {ENV_RUNTIME_DIR} to a directory of yours whose parents only you and root can write"
            raise RuntimeDirError(f"the EMOS runtime directory {root}{via} cannot be used: its parent {parent} "
                                  f"{problem}, so another user could replace it mid-run; {hint}")


_PROC = Path("/proc")


def _start_token(pid: int) -> int | None:
    """What tells process ``pid`` from a later one with the same pid (None: no such process).

    On Linux, its start in clock ticks since boot (/proc/PID/stat, field 22), which never
    changes. Not psutil's ``create_time()``: that adds /proc/stat's ``btime``, a whole number of
    seconds (wall clock minus uptime) that moves when the wall clock jumps against the boot clock
    (NTP, a VM paused and resumed), and then every live run looked dead at once and the next
    launcher's sweep removed their directories (a loaded test run lost three systems, ten tests,
    that way). Elsewhere than Linux, psutil's start time in 1/100 s."""
    try:
        text = (_PROC / str(pid) / "stat").read_text()
    except FileNotFoundError:
        if _PROC.is_dir():
            return None  # no such process
    except OSError:
        pass
    else:
        # The command name (field 2) may hold spaces and parentheses: the fields after it follow
        # the last ')'. Field 3 (state) is the first of them, field 22 (starttime) the 20th.
        fields = text[text.rfind(")") + 2 :].split()
        if len(fields) >= 20 and fields[19].isdigit():
            return None if fields[0] == "Z" else int(fields[19])
    try:
        return int(psutil.Process(pid).create_time() * 100)
    except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
        return None


def make_run_id(pid: int | None = None) -> str:
    pid = os.getpid() if pid is None else pid
    token = _start_token(pid)
    if token is None:
        raise RuntimeError(f"cannot read the start time of pid {pid}")
    return f"{pid}-{token}"


def run_is_alive(run_id: str) -> bool:
    m = _RUN_ID_RE.match(run_id)
    if not m:
        return False
    pid, token = int(m.group(1)), int(m.group(2))
    return _start_token(pid) == token


class RunContext:
    """The run this process belongs to. Children of a launcher inherit it through the environment."""

    def __init__(self, run_id: str, run_dir: Path, owner: bool):
        self.run_id = run_id
        self.run_dir = run_dir
        # Ownership is tied to the pid: a forked child inherits this object (and atexit
        # handlers) but must never delete the run it merely belongs to.
        self._owner_pid = os.getpid() if owner else -1
        self.shm_prefix = f"{SHM_PREFIX}{run_id}."
        for sub in ("wake", "subs", "ctl", "srv"):
            if owner:
                (run_dir / sub).mkdir(mode=0o700, parents=True, exist_ok=True)
            elif run_dir.is_dir():
                # A process joining a run never creates its directory: an observer of a run that
                # has just ended must not bring the removed directory back.
                (run_dir / sub).mkdir(mode=0o700, exist_ok=True)

    @property
    def owner(self) -> bool:
        return self._owner_pid == os.getpid()

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def create(cls) -> RunContext:
        """A new run owned by this process; sweeps what dead runs left behind first."""
        sweep_stale_runs()
        run_id = make_run_id()
        run_dir = runtime_root() / run_id
        run_dir.mkdir(mode=0o700, exist_ok=True)
        ctx = cls(run_id, run_dir, owner=True)
        atexit.register(ctx.remove_everything)
        return ctx

    @classmethod
    def from_env(cls) -> RunContext | None:
        run_dir = os.environ.get(ENV_RUN_DIR)
        run_id = os.environ.get(ENV_RUN_ID)
        if not run_dir or not run_id:
            return None
        return cls(run_id, Path(run_dir), owner=False)

    def export_env(self) -> None:
        """Make processes started from here join this run."""
        os.environ[ENV_RUN_DIR] = str(self.run_dir)
        os.environ[ENV_RUN_ID] = self.run_id

    # -- names ---------------------------------------------------------------------------------
    def segment_name(self, topic: str, publisher_id: str, generation: int) -> str:
        return f"{self.shm_prefix}{encode_name(topic)}.{encode_name(publisher_id)}.g{generation}"

    def topic_segments(self, topic: str) -> list[str]:
        prefix = f"{self.shm_prefix}{encode_name(topic)}."
        return sorted(n for n in _list_shm() if n.startswith(prefix))

    def all_segments(self) -> list[str]:
        return sorted(n for n in _list_shm() if n.startswith(self.shm_prefix))

    def subscriber_dir(self, topic: str) -> Path:
        path = self.run_dir / "subs" / encode_name(topic)
        path.mkdir(mode=0o700, exist_ok=True)
        return path

    # -- clean-up ------------------------------------------------------------------------------
    def remove_everything(self) -> int:
        """Unlink every segment and the run directory; returns how many segments were removed.

        Never raises: what cannot be removed (a name another user planted in our namespace) is
        logged and skipped, and everything else is still removed.
        """
        if not self.owner:
            return 0
        removed = remove_segments(self.shm_prefix)
        remove_run_dir(self.run_dir)
        return removed


def encode_name(name: str) -> str:
    """A topic or publisher name as a file-name-safe token (reversible)."""
    out = []
    for ch in name.strip("/") or "_":
        if ch.isalnum() or ch in "_-":
            out.append(ch)
        elif ch == "/":
            out.append("~")
        else:
            out.append(f"%{ord(ch):02X}")
    return "".join(out)


def decode_name(token: str) -> str:
    out, i = [], 0
    while i < len(token):
        ch = token[i]
        if ch == "~":
            out.append("/")
        elif ch == "%":
            out.append(chr(int(token[i + 1 : i + 3], 16)))
            i += 2
        else:
            out.append(ch)
        i += 1
    return "/" + "".join(out)


def _list_shm() -> Iterator[str]:
    try:
        return iter(os.listdir(SHM_DIR))
    except FileNotFoundError:
        return iter(())


def remove_segments(prefix: str) -> int:
    """Unlink our segments named ``<prefix>...``; returns how many. Entries that are not regular
    files of ours (planted by another user) are left alone with a warning; never raises."""
    removed = 0
    for name in _list_shm():
        if name.startswith(prefix):
            reason = remove_owned(SHM_DIR / name, mode=None)
            if reason is None:
                removed += 1
            else:
                rate_limited.warning(f"left:{name}", "clean-up: leaving %s in place: it %s", SHM_DIR / name, reason)
    return removed


def remove_run_dir(run_dir: Path) -> bool:
    """Remove a run directory, carrying on past anything that fails (each failure logged)."""

    def report(_func: object, path: str, exc_info: object) -> None:
        exc = exc_info[1] if isinstance(exc_info, tuple) else exc_info
        log.warning("clean-up: cannot remove %s: %s", path, exc)

    if not run_dir.exists():
        return True
    shutil.rmtree(run_dir, onerror=report)
    return not run_dir.exists()


def _our_regular_file(path: Path) -> bool:
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return False
    return stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid()


def sweep_stale_runs() -> list[str]:
    """Remove segments and run directories of runs whose owner process is gone.

    Only regular files of our own uid count: another user's files and directories (a forged
    ``emos.1-1.x``) are not ours to judge or remove, and must not stop our run from starting.
    """
    dead: set[str] = set()
    for name in _list_shm():
        if name.startswith(SHM_PREFIX):
            run_id = name[len(SHM_PREFIX) :].split(".", 1)[0]
            if run_id not in dead and _our_regular_file(SHM_DIR / name) and not run_is_alive(run_id):
                dead.add(run_id)
    root: Path | None
    try:
        root = runtime_root()
        for entry in root.iterdir():
            if _RUN_ID_RE.match(entry.name) and not run_is_alive(entry.name):
                dead.add(entry.name)
    except OSError as exc:
        log.warning("clean-up: not sweeping stale run directories: %s", exc)
        root = None
    for run_id in sorted(dead):
        remove_segments(f"{SHM_PREFIX}{run_id}.")
        if root is not None:
            remove_run_dir(root / run_id)
    return sorted(dead)


_default: RunContext | None = None
_default_lock = threading.Lock()


def current() -> RunContext:
    """The run of this process: inherited from a launcher, or created (and owned) on first use."""
    global _default
    with _default_lock:
        if _default is None or (_default.owner and not _default.run_dir.exists()):
            _default = RunContext.from_env() or RunContext.create()
        return _default


def set_current(ctx: RunContext | None) -> None:
    global _default
    with _default_lock:
        _default = ctx

