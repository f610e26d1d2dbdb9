"""Everything a component starts dies with it and is reaped.

Why subreapers and process groups, not cgroups: a cgroup v2 per worker would catch every
descendant too, but it needs a writable, delegated cgroup v2 hierarchy, which a robot's user
session often lacks (root in a container may have one; an ordinary user seldom does). A child
subreaper needs no privilege, so:

* **Every worker is a child subreaper.** Right after the zygote forks it, a worker calls
  ``setsid()`` (its pid is its process group and session id) and
  ``prctl(PR_SET_CHILD_SUBREAPER)`` (the flag is per process and not inherited, so the worker
  sets it itself; the zygote must not, or workers would be re-parented to it). An orphan among
  its descendants (the daemon of a double fork that called ``setsid`` and cleared its
  environment, say) is re-parented to the worker, not to the launcher: while the worker lives,
  everything it started is in its process tree.
* **A worker that ends cleans up itself.** Returning, raising, or on SIGTERM (the node's
  handler makes that a return), the worker stops (SIGSTOP, top-down, so nothing forks
  meanwhile) and then SIGKILLs every descendant, and reaps them before it exits.
* **A worker that is SIGKILLed** cannot, and its children (with their subtrees) are re-parented
  to the next subreaper up: the launcher. When the worker's pidfd says it ended, the launcher
  SIGKILLs its process group (*before* reaping the worker: an unreaped worker is a zombie that
  keeps its pid, hence the group id, from being reused), then kills, subtree and all, each
  child of the launcher that belonged to the worker:

  - its process group or its session is the worker's;
  - it was a direct child of the worker at the launcher's last sweep (the launcher notes, five
    times a second, each live worker's children with their start times);
  - its environment names the worker (``EMOS_WORKER_PID``);
  - when no component of the run is a thread of the launcher: it is in a session other than
    the launcher's. Live workers are subreapers, so nothing of theirs reaches the launcher,
    and the launcher itself forks no one into another session; such a child can only be an
    orphan of a worker that ended. (In a run with threaded components, their own children are
    the launcher's and may have left its session, so this rule is off there, and a daemon that
    left its worker's session and was less than one sweep old when its worker was SIGKILLed
    is killed at the end of the run.)
* **Reaping.** A worker reaps the zombies of processes it adopted, recognised as such because
  its sweep (every half second) saw them deeper in its tree first: it never waits for its own
  children, whose owners (``subprocess``, ``multiprocessing``) wait for them and would lose
  their exit status. (An orphan adopted and ended within one sweep stays a zombie until the
  worker ends.) The launcher reaps, five times a second and when a worker ends, the adopted
  processes that ended. (uvloop keeps SIGCHLD for itself.) It never waits for its own direct
  children (the zygote, and in threaded mode whatever a component started with
  ``subprocess``), whose owners wait for them.
* **End of the run.** Every child of the launcher that is neither a zygote nor older than the
  run is killed and reaped, pass after pass as their own children are re-parented to it. This
  also covers threaded mode, where components are threads of the launcher and their children
  are the launcher's own (so there the guarantee holds per run, not per restart).
* **Launcher SIGKILLed.** Workers get SIGTERM (parent-death signal) and clean up as above; the
  zygote kills the groups of the workers it forked last and the processes that name them in
  ``EMOS_WORKER_PID``.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable
from typing import NamedTuple

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


class ProcStat(NamedTuple):
    state: str
    ppid: int
    pgid: int
    sid: int
    start: int  # clock ticks since boot: with the pid, names one process (pids are reused)


def proc_stat(pid: int) -> ProcStat | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    # ``pid (comm) state ppid pgrp session ... starttime(22nd)``; comm may hold spaces and parentheses.
    fields = data[data.rfind(b")") + 2 :].split()
    try:
        return ProcStat(fields[0].decode(), int(fields[1]), int(fields[2]), int(fields[3]), int(fields[19]))
    except (IndexError, ValueError):
        return None


def kill_tree(root: int, include_root: bool = True) -> list[int]:
    """SIGKILL ``root``'s descendants (and ``root`` itself if asked); the pids signalled.

    Each process found is sent SIGSTOP first, walking down from ``root`` until a pass finds no
    one new: a process with a signal pending cannot complete a fork (the kernel restarts it),
    so once the walk is stable nothing can be born under the tree, and the SIGKILLs leave no
    survivor. Killed processes become zombies for their parents, or, if those died too, for the
    nearest subreaper, to reap.
    """
    seen: list[int] = [root] if include_root else []
    if include_root:
        _signal(root, signal.SIGSTOP)
    known = set(seen)
    for _ in range(1000):  # a fork bomb outpacing the walk ends here; the SIGKILLs still go out
        found = False
        stack = [root]
        while stack:
            for child in _children(stack.pop()):
                if child not in known:
                    known.add(child)
                    seen.append(child)
                    found = True
                    _signal(child, signal.SIGSTOP)
                stack.append(child)
        if not found:
            break
    for pid in seen:
        _signal(pid, signal.SIGKILL)
    return seen


def _signal(pid: int, sig: int) -> None:
    try:
        os.kill(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def end_descendants(timeout: float = 2.0) -> int:
    """A worker that ends: kill every process below it and reap them (it is their subreaper).

    Returns how many were killed. Waiting for every child here is safe: nothing in this
    process waits for them any more."""
    killed = kill_tree(os.getpid(), include_root=False)
    deadline = time.monotonic() + timeout
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            break  # no children left at all
        if pid == 0:
            if time.monotonic() >= deadline:
                break
            time.sleep(0.002)
    return len(killed)


class AdoptedReaper:
    """Inside a worker: reaps the zombies of the orphans it adopted as their subreaper.

    An orphan is recognised by having been seen deeper in the worker's tree (a grandchild or
    below) before it became a child: the worker's own children are children from birth, and
    their owners wait for them. A daemon thread does this every ``period`` seconds.
    """

    def __init__(self, period: float = 0.5):
        self.period = period
        self.deep: dict[int, int] = {}  # pid -> start time, of processes seen below a child
        self.reaped = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="emos:adopted-reaper", daemon=True)

    def start(self) -> AdoptedReaper:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            try:
                self.tick()
            except Exception:  # a /proc surprise must not end the thread
                log.debug("adopted-process sweep failed", exc_info=True)

    def tick(self) -> None:
        me = os.getpid()
        deep: dict[int, int] = {}
        for child in _children(me):
            stat = proc_stat(child)
            if stat is None:
                continue
            if stat.state in ("Z", "X"):
                if self.deep.get(child) == stat.start:
                    try:
                        if os.waitpid(child, os.WNOHANG)[0]:
                            self.reaped += 1
                    except ChildProcessError:
                        pass
                continue
            if self.deep.get(child) == stat.start:
                deep[child] = stat.start  # adopted and alive: keep it known
            stack = [child]
            while stack:
                for pid in _children(stack.pop()):
                    below = proc_stat(pid)
                    if below is not None:
                        deep[pid] = below.start
                        stack.append(pid)
        self.deep = deep


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
    before the run started (a recipe's own helpers) are never touched. ``threads_fork``: some
    components run as threads of the launcher, so children of the launcher in other sessions
    may be theirs (see the module notes).
    """

    def __init__(self, protected: Callable[[], Iterable[int]] = tuple, on_sweep: Callable[[], None] | None = None,
                 threads_fork: bool = True):
        self.protected = protected
        self.on_sweep = on_sweep  # the launcher's check of its protected zygotes, every tick
        self.threads_fork = threads_fork
        self.me = os.getpid()
        self.my_sid = os.getsid(0)
        self.preexisting = set(_children(self.me))
        self.live: set[int] = set()  # pids (= group and session ids) of running process workers
        self.groups: set[int] = set()  # every worker group of this run, for attributing zombies
        self.kids: dict[int, dict[int, int]] = {}  # live worker -> its children (pid -> start time) at the last sweep
        self.left: dict[int, int] = {}  # pid -> start time: children a worker had when it ended
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
        """Called once the worker is dead (its children are ours by now), before or after it is reaped."""
        self.live.discard(pid)
        self.left.update(self.kids.pop(pid, {}))
        self.sweep()

    def _note_kids(self) -> None:
        for worker in self.live:
            stat = proc_stat(worker)
            if stat is None or stat.state in ("Z", "X") or stat.ppid != self.me:
                continue  # ended, its end not handled yet: keep what it had at the last sweep
            kids = {}
            for pid in _children(worker):
                stat = proc_stat(pid)
                if stat is not None and stat.ppid == worker:
                    kids[pid] = stat.start
            self.kids[worker] = kids

    def _owner(self, pid: int, stat: ProcStat) -> int | None:
        """The worker ``pid`` (a child of the launcher) belonged to; -1: some worker that ended."""
        for run_id in (stat.pgid, stat.sid):
            if run_id in self.groups:
                return run_id
        if self.left.get(pid) == stat.start:
            return -1
        owner = _env_owner(pid)
        if owner is not None:
            return owner
        if not self.threads_fork and stat.sid != self.my_sid:
            return -1  # only an orphan of an ended worker can be here (see the module notes)
        return None

    def sweep(self) -> None:
        """One pass over our children; cheap (a few /proc reads), safe to call any time."""
        self._forget_empty_groups()
        protected = set(self.protected()) | self.preexisting
        children = _children(self.me)
        for pid in children:
            if pid in self.live or pid in protected:
                continue
            stat = proc_stat(pid)
            if stat is None:
                continue
            if stat.state in ("Z", "X"):
                if pid in self.adopted or self._owner(pid, stat) is not None:
                    self._reap(pid)
                continue
            owner = self._owner(pid, stat)
            if owner is None:
                continue  # not attributable now: the launcher's own (threaded mode), or see finish()
            self.adopted.add(pid)
            if owner not in self.live:
                who = f"component process {owner}" if owner > 0 else "a component process that ended"
                log.warning("killing pid %d and everything below it, left behind by %s", pid, who)
                for victim in kill_tree(pid):
                    self.adopted.add(victim)  # its zombie may come to us: reap it then
                    self.killed += 1
        present = set(children)
        self.left = {p: t for p, t in self.left.items() if p in present}
        self.adopted = {p for p in self.adopted if p in present or proc_stat(p) is not None}  # forget the gone
        if self.threads_fork:  # without threads, the session rule of _owner covers these too
            self._note_kids()

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
            left = [p for p in _children(self.me) if p not in exempt]
            if not left:
                return
            for pid in left:
                stat = proc_stat(pid)
                if stat is not None and stat.state in ("Z", "X"):
                    self._reap(pid)
                    continue
                try:
                    os.kill(pid, signal.SIGKILL)
                    self.killed += 1
                except ProcessLookupError:
                    pass
            time.sleep(0.005)
        log.error("processes %s outlived the run's clean-up", [p for p in _children(self.me) if p not in exempt])
