"""Everything a component starts dies with it and is reaped.

Why process groups and not cgroups: a cgroup v2 per worker would also catch processes that
leave their group, but it needs a writable, delegated cgroup v2 hierarchy, which a robot's user
session often lacks (this machine has a read-only cgroup v1 mount). Process groups need
nothing, so:

* **One session per worker.** Each worker calls ``setsid()`` right after the zygote forks it:
  its pid is its process group id, and everything it starts inherits the group.
* **The group dies with the worker.** When the worker's pidfd says it ended, the supervisor
  SIGKILLs the group *before* reaping the worker: an unreaped worker is a zombie that keeps its
  pid, hence the group id, from being reused, so the signal cannot hit a stranger's group.
  Stopping a worker sends SIGTERM to the whole group (every process gets the polite stop, as a
  terminal's Ctrl-C does), a hang SIGKILL.
* **Escapees are ours anyway.** A child that leaves the group (``setsid``, ``setpgid``) is still
  a descendant of the launcher, which is a child subreaper: once its parent dies it is
  re-parented to the launcher. Workers export ``EMOS_WORKER_PID`` to what they execute; an
  adopted process whose group is a worker's, or whose environment names a worker, belongs to
  that worker and is killed once that worker is gone. (A process that leaves the group and
  does not show the variable in ``/proc/<pid>/environ``, because it cleared its environment or
  was forked without ``exec``, is killed only at the end of the run: the one case a cgroup
  would catch earlier.)
* **Reaping.** The launcher reaps, five times a second and when a worker ends, the adopted
  processes that ended: the zombies no one else would wait for. (uvloop keeps SIGCHLD for
  itself.) It never waits for its own direct children (the zygote, and in threaded mode
  whatever a component started with ``subprocess``), whose owners wait for them.
* **End of the run.** Every child of the launcher that is neither a zygote nor older than the
  run is killed and reaped, pass after pass as their own children are re-parented to it. This
  also covers threaded mode, where components are threads of the launcher and their children
  are the launcher's own (so there the guarantee holds per run, not per restart).
* **Launcher SIGKILLed.** Workers get SIGTERM (parent-death signal); the zygote kills the groups
  of the workers it forked last and the processes that name them in ``EMOS_WORKER_PID``.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import time
from typing import Callable, Iterable

import psutil

log = logging.getLogger("emos.supervisor")

ENV_WORKER_PID = "EMOS_WORKER_PID"
SWEEP_PERIOD_S = 0.2


def kill_group(pgid: int, sig: int) -> None:
    """Signal process group ``pgid``; a group that no longer exists is fine."""
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _children(pid: int) -> list[int]:
    """Direct children of ``pid`` (``/proc/<pid>/task/*/children``, no walk of all processes)."""
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                out.extend(int(x) for x in f.read().split())
        except FileNotFoundError:  # a kernel without CONFIG_PROC_CHILDREN: scan every process
            try:
                return [c.pid for c in psutil.Process(pid).children()]
            except psutil.Error:
                return []
        except OSError:
            continue
    return out


def _state_and_pgid(pid: int) -> tuple[str, int] | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    # ``pid (comm) state ppid pgrp ...``; comm may hold spaces and parentheses.
    fields = data[data.rfind(b")") + 2 :].split()
    return fields[0].decode(), int(fields[2])


def _env_owner(pid: int) -> int | None:
    try:
        value = psutil.Process(pid).environ().get(ENV_WORKER_PID)
    except (psutil.Error, OSError):
        return None
    return int(value) if value and value.isdigit() else None


def kill_worker_trees(worker_pids: Iterable[int]) -> None:
    """SIGKILL the process groups of ``worker_pids`` and the processes of this user whose
    environment names one of them (those that left the group). For the zygote when the launcher
    died, so no subreaper collects what the workers leave."""
    owners = {str(p) for p in worker_pids}
    for pid in owners:
        kill_group(int(pid), signal.SIGKILL)
    uid = os.getuid()
    for proc in psutil.process_iter(["uids"]):
        try:
            if proc.pid != os.getpid() and proc.info["uids"] is not None and proc.info["uids"].real == uid and proc.environ().get(ENV_WORKER_PID) in owners:
                proc.kill()
        except (psutil.Error, OSError):
            continue


class OrphanReaper:
    """The launcher's side: kills what dead workers left behind and reaps adopted processes.

    ``protected()`` returns pids the reaper must leave alone (the zygotes). Workers are
    registered with :meth:`worker_started` / :meth:`worker_ended`. Children the launcher had
    before the run started (a recipe's own helpers) are never touched.
    """

    def __init__(self, protected: Callable[[], Iterable[int]] = tuple, on_sweep: Callable[[], None] | None = None):
        self.protected = protected
        self.on_sweep = on_sweep  # the launcher's check of its protected zygotes, every tick
        self.preexisting = set(_children(os.getpid()))
        self.live: set[int] = set()  # pids (= group ids) of running process workers
        self.groups: set[int] = set()  # every worker group of this run, for attributing zombies
        self.adopted: set[int] = set()  # processes we attributed to a worker (zombie reaping)
        self.killed = 0
        self.reaped = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timer: asyncio.TimerHandle | None = None

    def install(self, loop: asyncio.AbstractEventLoop) -> None:
        """Sweep every ``SWEEP_PERIOD_S`` and whenever a worker ends. (uvloop keeps SIGCHLD for
        itself, and a sweep is a few /proc reads, so a short period costs nothing.)"""
        self._loop = loop
        self._timer = loop.call_later(SWEEP_PERIOD_S, self._tick)

    def _tick(self) -> None:
        try:
            if self.on_sweep is not None:
                self.on_sweep()
            self.sweep()
        except Exception:  # never let a /proc surprise stop the sweeps
            log.exception("orphan sweep failed")
        if self._loop is not None:
            self._timer = self._loop.call_later(SWEEP_PERIOD_S, self._tick)

    def uninstall(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._loop = None

    def worker_started(self, pid: int) -> None:
        self.live.add(pid)
        self.groups.add(pid)

    def worker_ended(self, pid: int) -> None:
        self.live.discard(pid)
        self.sweep()

    def sweep(self) -> None:
        """One pass over our children; cheap (a few /proc reads), safe to call any time."""
        self._forget_empty_groups()
        protected = set(self.protected()) | self.preexisting
        for pid in _children(os.getpid()):
            if pid in self.live or pid in protected:
                continue
            stat = _state_and_pgid(pid)
            if stat is None:
                continue
            state, pgid = stat
            if state in ("Z", "X"):
                if pid in self.adopted or pgid in self.groups:
                    self._reap(pid)
                continue
            owner = pgid if pgid in self.groups else _env_owner(pid)
            if owner is None:
                continue  # not attributable now: the launcher's own (threaded mode), or see finish()
            self.adopted.add(pid)
            if owner not in self.live:
                log.warning("killing pid %d, left behind by component process %d", pid, owner)
                try:
                    os.kill(pid, signal.SIGKILL)
                    self.killed += 1
                except ProcessLookupError:
                    pass

    def _forget_empty_groups(self) -> None:
        """A dead worker's group id is remembered only while processes (zombies included) still
        carry it: once empty, the number may be reused by a process that is none of ours."""
        for pgid in self.groups - self.live:
            try:
                os.killpg(pgid, 0)
            except (ProcessLookupError, PermissionError):
                self.groups.discard(pgid)

    def _reap(self, pid: int) -> None:
        try:
            done, _ = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            done = pid
        if done:
            self.adopted.discard(pid)
            self.reaped += 1

    def finish(self, timeout: float = 3.0) -> None:
        """End of the run: kill and reap every child the run gave us.

        With all workers gone, each child of the launcher that is neither a zygote nor older
        than the run is a component's leftover (adopted, or started by a component thread). As
        each dies, its own children are re-parented to us (subreaper) and go in the next pass.
        """
        self.live.clear()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            exempt = set(self.protected()) | self.preexisting
            left = [p for p in _children(os.getpid()) if p not in exempt]
            if not left:
                return
            for pid in left:
                stat = _state_and_pgid(pid)
                if stat is not None and stat[0] in ("Z", "X"):
                    self._reap(pid)
                    continue
                try:
                    os.kill(pid, signal.SIGKILL)
                    self.killed += 1
                except ProcessLookupError:
                    pass
            time.sleep(0.005)
        log.error("processes %s outlived the run's clean-up", [p for p in _children(os.getpid()) if p not in exempt])
