"""Fast DDS's shared-memory files left behind by participants that died without closing.

Fast DDS's shared-memory transport keeps, in ``/dev/shm``, a segment per participant
(``fastrtps_<hex>``) and a segment per port (``fastrtps_port<N>``), each with a lock file beside
it (``<name>_el``) and, for ports, a semaphore (``sem.fastrtps_port<N>_mutex``). A participant
holds a ``flock`` on the lock file of every segment it owns or uses for as long as it lives, and
the kernel drops that lock when the process dies, SIGKILL included. A lock file nobody holds a
lock on therefore marks a segment no live participant uses: a leftover. This is the test Fast
DDS's own ``fastdds shm clean`` applies; we apply it where the bridge starts (a bridge SIGKILLed
and restarted by the supervisor removes what its predecessor left).

The files are untrusted: only regular files owned by this user are considered (a symlink or
another user's file is left alone), and lock files younger than :data:`MIN_AGE_S` (by their
modification time: Fast DDS creates them empty and never writes them) are skipped, so a participant
that has created its lock file but not yet locked it is never mistaken for a dead one.
"""
from __future__ import annotations

import fcntl
import os
import stat
import time

SHM_DIR = "/dev/shm"
PREFIXES = ("fastrtps_", "fastdds_")
LOCK_SUFFIX = "_el"
MIN_AGE_S = 5.0


def _companions(base: str) -> tuple[str, ...]:
    """The files of one segment, lock file last (it is what marks the others as ours to remove)."""
    return base, f"sem.{base}_mutex", base + LOCK_SUFFIX


def remove_leftovers(shm_dir: str = SHM_DIR, min_age_s: float = MIN_AGE_S) -> list[str]:
    """Remove the Fast DDS segments no live process holds; returns the names removed."""
    removed: list[str] = []
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return removed
    uid, now = os.getuid(), time.time()
    for name in names:
        if not name.startswith(PREFIXES) or not name.endswith(LOCK_SUFFIX):
            continue
        try:
            fd = os.open(os.path.join(shm_dir, name), os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue  # gone meanwhile, a symlink, or not ours to read
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_uid != uid or now - st.st_mtime < min_age_s:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue  # a live participant holds it
            except OSError:
                continue
            # Held by us now: a participant opening the segment meanwhile waits for this lock.
            for victim in _companions(name[: -len(LOCK_SUFFIX)]):
                path = os.path.join(shm_dir, victim)
                try:
                    if stat.S_ISREG(os.lstat(path).st_mode):
                        os.unlink(path)
                        removed.append(victim)
                except OSError:
                    pass
        finally:
            os.close(fd)
    return removed
