"""Process faults: kills, hangs, starvation, the zygote and whole groups.

Targets are component names, ``random`` (seeded), or ``each`` (every component in turn).
Signals go to the pid the supervisor reports at the moment of the fault, and the old pid is
recorded so the checker can tell the restarted process from the one that was hit.
"""
from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

import psutil

from emos.chaos.history import Record
from emos.chaos.nemesis.base import Nemesis, NemesisError
from emos.core.discovery import supervisor_nodes, worker_nodes


def _signal(value: str | int) -> signal.Signals:
    try:
        return signal.Signals(value) if isinstance(value, int) else signal.Signals[value if value.startswith("SIG") else "SIG" + value]
    except (KeyError, ValueError):
        raise NemesisError(f"unknown signal {value!r}; use a name such as SIGKILL or SIGTERM") from None


class _Targeted(Nemesis):
    def __init__(self, target: str = "random", exclude: list[str] | None = None, **params: Any) -> None:
        super().__init__(target=target, **({"exclude": exclude} if exclude else {}), **params)
        if not isinstance(target, str) or not target:
            raise NemesisError(f"{self.kind}: target must be a component name, 'random' or 'each', got {target!r}")
        self.target = target
        self.exclude = set(exclude or [])
        self._turn = 0
        self._seen: set[str] = set()  # every component name the tree has listed during the run

    def pick(self) -> tuple[str, int] | None:
        """(component, pid) to hit now, or None when nothing is running."""
        assert self.system is not None
        tree = worker_nodes(self.system.tree()["tree"])
        known = {w["name"] for w in tree}
        self._seen |= known
        # Threads cannot be signalled separately; a stopped or restarting worker has no pid now.
        workers = {w["name"]: w.get("pid") for w in tree if w.get("mode", "process") == "process"}
        if self.target not in ("random", "each") and self.target not in known:
            if self.target in self._seen:
                return None  # it was there: its group was given up (escalation), nothing to hit now
            raise NemesisError(f"{self.kind}: no component named {self.target!r}; components: {', '.join(sorted(known))}")
        names = sorted(n for n, pid in workers.items() if pid and n not in self.exclude)
        if self.target == "random":
            name = self.rng.choice(names) if names else None
        elif self.target == "each":
            name = names[self._turn % len(names)] if names else None
            self._turn += 1
        else:
            name = self.target
        pid = workers.get(name) if name else None
        return (name, pid) if name and pid else None

    def signal_target(self, sig: signal.Signals) -> tuple[str, int] | None:
        """Pick a target and send it ``sig``; None when nothing (alive) was there to hit."""
        hit = self.pick()
        if hit is None:
            return None
        try:
            os.kill(hit[1], sig)
        except ProcessLookupError:
            return None
        return hit


class KillComponent(_Targeted):
    kind = "kill"
    summary = "send a signal (default SIGKILL) to a component's process"
    expects = "restart"

    def __init__(self, target: str = "random", signal: str = "SIGKILL", **params: Any) -> None:
        super().__init__(target, signal=signal, **params)
        self.sig = _signal(signal)

    def start(self) -> Record | None:
        hit = self.signal_target(self.sig)
        if hit is None:
            return None
        name, pid = hit
        record = self._fault(target=name, pid=pid, signal=self.sig.name)
        self.active = None  # nothing lasts: a kill has no stop
        return record


class HangComponent(_Targeted):
    """SIGSTOP: the process stays alive but silent, as a deadlock would leave it. Its heartbeat
    stops, so the supervisor must detect the hang and replace it; ``stop`` continues the process
    if it is still there (the supervisor may already have killed it)."""

    kind = "hang"
    summary = "freeze a component with SIGSTOP until its hang is detected"
    expects = "restart"

    def start(self) -> Record | None:
        hit = self.signal_target(signal.SIGSTOP)
        if hit is None:
            return None
        name, pid = hit
        self._pid = pid
        return self._fault(target=name, pid=pid)

    def stop(self) -> None:
        if self.active is not None:
            try:
                os.kill(self._pid, signal.SIGCONT)
            except ProcessLookupError:
                pass
        super().stop()


class StarveComponent(_Targeted):
    """CPU starvation: the process is stopped ``duty`` of every ``period`` seconds, as a
    neighbour hogging the core would do. It should keep working, slower."""

    kind = "starve"
    summary = "duty-cycled SIGSTOP/SIGCONT of a component (CPU starvation)"
    expects = "healthy"

    def __init__(self, target: str = "random", duty: float = 0.5, period: float = 0.2, **params: Any) -> None:
        super().__init__(target, duty=duty, period=period, **params)
        if not 0.0 < float(duty) < 1.0 or float(period) <= 0:
            raise NemesisError(f"starve: duty must be in (0, 1) and period > 0, got duty={duty!r} period={period!r}")
        self.duty, self.period = float(duty), float(period)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> Record | None:
        hit = self.pick()
        if hit is None:
            return None
        name, pid = hit
        self._stop.clear()
        self._thread = threading.Thread(target=self._cycle, args=(pid,), name="chaos-starve", daemon=True)
        self._thread.start()
        return self._fault(target=name, pid=pid)

    def _cycle(self, pid: int) -> None:
        try:
            while not self._stop.is_set():
                os.kill(pid, signal.SIGSTOP)
                self._stop.wait(self.period * self.duty)
                os.kill(pid, signal.SIGCONT)
                self._stop.wait(self.period * (1.0 - self.duty))
        except ProcessLookupError:
            pass
        finally:
            try:
                os.kill(pid, signal.SIGCONT)
            except ProcessLookupError:
                pass

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        super().stop()


class KillZygote(Nemesis):
    """SIGKILL the zygote that forks component processes; its spare must take over."""

    kind = "kill_zygote"
    summary = "SIGKILL the zygote (its spare must take over)"
    expects = "zygote"

    def start(self) -> Record | None:
        assert self.system is not None
        zygotes = []
        for pid in self.system.zygote_pids():
            try:
                zygotes.append((psutil.Process(pid).create_time(), pid))
            except psutil.Error:
                pass
        if not zygotes:
            return None
        _, pid = min(zygotes)  # the oldest is the one in service; younger ones are spares
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            return None
        record = self._fault(target="zygote", pid=pid, zygotes_before=[p for _, p in zygotes])
        self.active = None
        return record


class KillGroup(Nemesis):
    """SIGKILL every process component of one supervisor group at once."""

    kind = "kill_group"
    summary = "SIGKILL every component of a supervisor group at once"
    expects = "restart"

    def __init__(self, group: str | None = None, **params: Any) -> None:
        super().__init__(group=group, **params)
        self.group = group

    def start(self) -> Record | None:
        assert self.system is not None
        tree = self.system.tree()["tree"]
        groups = {g["name"]: g for g in supervisor_nodes(tree) if g is not tree}
        if not groups:
            return None
        name = self.group or self.rng.choice(sorted(groups))
        if name not in groups:
            raise NemesisError(f"kill_group: no supervisor group {name!r}; groups: {', '.join(sorted(groups))}")
        victims = {w["name"]: w["pid"] for w in worker_nodes(groups[name]) if w.get("pid") and w.get("mode") == "process"}
        for pid in victims.values():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        records = [self._fault(target=comp, pid=pid, group=name) for comp, pid in victims.items()]
        self.active = None
        time.sleep(0)  # records share one instant; the checker judges each component
        return records[0] if records else None


class TermDeafComponent(_Targeted):
    """A process that does not answer SIGTERM: the target is frozen (SIGSTOP, so the SIGTERM of a
    polite stop stays pending) and the supervisor is asked to restart it through its control
    socket. The stop must escalate to SIGKILL after the stop timeout (or the hang be caught by the
    heartbeat first), and a new process must come up; a supervisor that waits forever on the
    SIGTERM fails the check."""

    kind = "term_deaf"
    summary = "freeze a component, then ask the supervisor to restart it (its SIGTERM goes unanswered)"
    expects = "restart"

    def start(self) -> Record | None:
        from emos.core.rpc import RpcClient

        assert self.system is not None and self.system.run_dir is not None
        hit = self.signal_target(signal.SIGSTOP)
        if hit is None:
            return None
        name, pid = hit
        self._pid = pid
        record = self._fault(target=name, pid=pid)
        with RpcClient(self.system.run_dir / "supervisor.sock", timeout=2.0) as rpc:
            rpc.call("lifecycle", component=name, request="restart", wait=False, by="chaos")
        return record

    def stop(self) -> None:
        if self.active is not None:
            try:
                os.kill(self._pid, signal.SIGCONT)
            except ProcessLookupError:
                pass
        super().stop()


class KillMonitor(KillComponent):
    """SIGKILL the Monitor (``emos_monitor``, the component that evaluates events); it must be
    restarted and its events armed again (``handle_once`` events stay spent)."""

    kind = "kill_monitor"
    summary = "SIGKILL the events Monitor (emos_monitor)"

    def __init__(self, signal: str = "SIGKILL", **params: Any) -> None:
        super().__init__(target="emos_monitor", signal=signal, **params)
