"""A running system: the run context, the zygote, the supervision tree and its control socket.

``System.run()`` is what ``Launcher.bringup()`` calls. Exit codes say how it ended:
0 stopped on request (signal, duration or ``emos`` stop), 3 the root supervisor gave up
(restart intensity breached at the top), 4 a component failed to start.
"""
from __future__ import annotations

import asyncio
import collections
import logging
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from attrs import define, field

from emos.core import control as C
from emos.core.component import BaseComponent
from emos.core.node import ENV_SUPERVISOR_SOCKET, Node
from emos.core.prctl import become_subreaper
from emos.core.rpc import CONTROL_FRAME, RpcServer
from emos.core.wiring import check_system
from emos.ratelimit import RateLimitedLog
from emos.supervisor.fallback_driver import FallbackDriver
from emos.supervisor.heartbeat import HeartbeatMonitor
from emos.supervisor.orchestration import Orchestration, fallback_summary, lifecycle_op, with_monitor
from emos.supervisor.pristine import pristine_copy
from emos.supervisor.reaper import OrphanReaper
from emos.supervisor.spawn import Zygote
from emos.supervisor.tree import ChildSpec, RestartLedger, RestartType, StartFailed, Strategy, Supervisor, supervisor_spec
from emos.supervisor.workers import ProcessWorker, ThreadWorker
from emos.transport.context import RunContext, remove_run_dir, remove_segments, set_current
from emos.transport.waker import sweep_dead_wakers

log = logging.getLogger("emos.supervisor")
WAKERS_SWEEP_S = 5.0  # how often the launcher removes the wake-up files of readers killed outright

EXIT_OK, EXIT_GAVE_UP, EXIT_START_FAILED = 0, 3, 4


@define(kw_only=True)
class SupervisionPolicy:
    """How one group of components (one ``add_pkg``) is supervised."""

    strategy: Strategy = field(default=Strategy.ONE_FOR_ONE, converter=Strategy)
    max_restarts: int = 5
    max_seconds: float = 10.0
    restart: RestartType = field(default=RestartType.PERMANENT, converter=RestartType)


@define(kw_only=True)
class Package:
    components: list[BaseComponent]
    multiprocessing: bool
    activate: bool = True
    policy: SupervisionPolicy = field(factory=SupervisionPolicy)
    name: str = ""
    # How the root treats the group itself: "temporary" for the launcher's monitor (a Cortex),
    # whose group is dropped, not restarted, when it breaches its intensity (the run goes on).
    group_restart: RestartType = field(default=RestartType.PERMANENT, converter=RestartType)


@define(kw_only=True)
class SystemOptions:
    heartbeat_timeout: float = 2.0
    start_timeout: float = 30.0
    # Activation may wait for the component's own resources (an embedding model: 17-85 s on a
    # busy machine; BaseComponent.custom_on_activate): a hang bound, not a budget.
    activate_timeout: float = 300.0
    stop_timeout: float = 5.0
    max_restarts: int = 3  # of whole groups, at the root
    max_seconds: float = 30.0
    duration: float | None = None  # stop by itself after this many seconds


class System:
    def __init__(self, packages: list[Package], options: SystemOptions | None = None, orchestration: Orchestration | None = None):
        self.orchestration = orchestration or Orchestration()
        self.packages = with_monitor(packages, self.orchestration)
        self.options = options or SystemOptions()
        self.components: list[BaseComponent] = [c for p in self.packages for c in p.components]
        names = [c.component_name for c in self.components]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"component names must be unique in a system; repeated: {', '.join(dupes)}")
        check_system(self.components)  # topic types agree, names fit: before anything starts
        self._pristine: dict[int, BaseComponent] = {}
        self.events: collections.deque[dict[str, Any]] = collections.deque(maxlen=2000)
        self.exit_code = EXIT_OK
        self.exit_reason = ""
        self.zygote: Zygote | None = None
        self._wakers_swept_at = time.monotonic()
        # (component, pid) -> (the future its hello completes, the incarnation waiting on it).
        # Keyed by pid too: a hello completes only the start of the process that sent it, never
        # a later start of the same component (the observed race: a copy killed while starting
        # said hello and drove the start of its successor).
        self._hellos: dict[tuple[str, int], tuple[asyncio.Future[int], Any]] = {}
        self._stale_hellos = RateLimitedLog(log, interval=5.0)  # a peer may repeat them: say so once per interval
        self._stop_requested: asyncio.Event | None = None
        self.root: Supervisor | None = None
        self.up = False  # every group started (the tree lists a group only once it is up)
        self.ledger = RestartLedger()  # every (re)start of every child, over the whole run
        self.incarnations: dict[str, Any] = {}  # component name -> its running worker (process or thread)

    # ------------------------------------------------------------------ entry point
    def run(self) -> int:
        import uvloop

        self.ctx = RunContext.create()
        self.ctx.export_env()
        set_current(self.ctx)
        self.control_path = self.ctx.run_dir / "supervisor.sock"
        os.environ[ENV_SUPERVISOR_SOCKET] = str(self.control_path)
        become_subreaper()
        self.reaper = OrphanReaper(protected=self._zygote_pids, on_sweep=self._on_sweep,
                                   threads_fork=not all(p.multiprocessing for p in self.packages))
        try:
            process_indices = [i for i, c in enumerate(self.components) if self._mode(i) == "process"]
            if process_indices:
                # Forked first, while this process still has one thread and no event loop.
                prefix, run_dir = self.ctx.shm_prefix, self.ctx.run_dir

                def janitor() -> None:  # the zygote's clean-up when the launcher died under it
                    remove_segments(prefix)
                    remove_run_dir(run_dir)

                self.zygote = Zygote(
                    [self._process_target(i) for i in range(len(self.components))],
                    [c.component_name for c in self.components],
                    janitor=janitor,
                )
                self.zygote.start()
            for i, c in enumerate(self.components):
                if self._mode(i) == "thread":
                    self._pristine[i] = pristine_copy(c)
            loop = uvloop.new_event_loop()
            asyncio.set_event_loop(loop)
            try:
                loop.run_until_complete(self._main())
            finally:
                loop.close()
        finally:
            if self.zygote is not None:
                self.zygote.stop()
            self.reaper.finish()
            removed = self.ctx.remove_everything()
            log.debug("removed %d shared-memory segments", removed)
            set_current(None)
        return self.exit_code

    def _on_sweep(self) -> None:
        """Every reaper tick: replace a dead zygote; every WAKERS_SWEEP_S, remove the wake-up
        files of readers killed outright (``emos topic echo`` SIGKILLed before any publisher
        noticed: nothing else would until the run ends)."""
        if self.zygote is not None:
            self.zygote.replace_dead()
        now = time.monotonic()
        if now - self._wakers_swept_at >= WAKERS_SWEEP_S:
            self._wakers_swept_at = now
            try:
                sweep_dead_wakers(self.ctx)
            except OSError as exc:  # a vanished directory mid-sweep: the next sweep sees the rest
                log.warning("supervisor: sweeping wake-up files of dead readers failed: %s", exc)

    def _zygote_pids(self) -> list[int]:
        z = self.zygote
        return [h.pid for h in (z.primary, z.spare) if h is not None] if z is not None else []

    def _mode(self, index: int) -> str:
        i = index
        for pkg in self.packages:
            if i < len(pkg.components):
                return "process" if pkg.multiprocessing else "thread"
            i -= len(pkg.components)
        raise IndexError(index)

    def _process_target(self, index: int) -> Callable[[], int]:
        component = self.components[index]

        def target() -> int:
            return Node(component, ctx=self.ctx, supervisor_socket=str(self.control_path)).run()

        return target

    def fresh_component(self, index: int) -> BaseComponent:
        """What a start in threaded mode runs: a copy of the pristine copy made before anything
        ran. Without one (the component could not be copied, as was said then), the object."""
        original = self._pristine.get(index)
        if original is None:
            return pristine_copy(self.components[index])
        return original if original is self.components[index] else pristine_copy(original)

    # ------------------------------------------------------------------ main coroutine
    async def _main(self) -> None:
        loop = asyncio.get_running_loop()
        self._stop_requested = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self._on_signal, sig)
        self.reaper.install(loop)
        self.control = RpcServer(self.control_path, self._control_ops(), name="supervisor", max_frame=CONTROL_FRAME)
        await self.control.start()
        from emos.transport.zenoh_status import start_status_bridge, stop_status_bridge

        status_bridge = start_status_bridge(self.ctx.run_dir, self.ctx.run_id)  # `emos status --remote`; None unless the run uses Zenoh
        self.heartbeats = HeartbeatMonitor(self.ctx, self.options.heartbeat_timeout)
        self.fallbacks = FallbackDriver(self, self.orchestration, lambda: self.root)
        self.root = self._build_root()
        try:
            try:
                await self.root.start()
            except StartFailed as exc:
                self.exit_code, self.exit_reason = EXIT_START_FAILED, str(exc)
                log.error("start-up failed: %s", exc)
                return
            self.up = True
            log.info("system up: %d components (run %s)", len(self.components), self.ctx.run_id)
            waiters: list[asyncio.Future[Any]] = [asyncio.ensure_future(self._stop_requested.wait()), self.root.exited]
            if self.options.duration:
                waiters.append(asyncio.ensure_future(self._stop_after(self.options.duration)))
            done, pending = await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
            for p in pending:
                if p is not self.root.exited:
                    p.cancel()
            if self.root.exited.done():
                result = self.root.exited.result()
                self.exit_code, self.exit_reason = EXIT_GAVE_UP, result.detail
                log.error("supervision gave up: %s", result.detail)
            else:
                self.exit_reason = self.exit_reason or "stopped on request"
                await self.fallbacks.close()  # no ladder acts on components being shut down
                await self.root.stop()
        finally:
            await self.fallbacks.close()
            self.heartbeats.close()
            await self.control.close()
            stop_status_bridge(status_bridge)
            self.reaper.uninstall()

    async def _stop_after(self, seconds: float) -> None:
        await asyncio.sleep(seconds)
        self.exit_reason = f"ran for the requested {seconds:g} s"

    def _on_signal(self, sig: int) -> None:
        log.info("%s received: stopping", signal.Signals(sig).name)
        self.exit_reason = f"{signal.Signals(sig).name} received"
        assert self._stop_requested is not None
        self._stop_requested.set()

    def request_stop(self, reason: str = "stopped on request") -> None:
        self.exit_reason = reason
        if self._stop_requested is not None:
            self._stop_requested.set()

    # ------------------------------------------------------------------ tree
    def _build_root(self) -> Supervisor:
        children = []
        offset = 0
        for k, pkg in enumerate(self.packages):
            name = pkg.name or f"group{k}"
            children.append(supervisor_spec(self._group_factory(pkg, offset, name), name, restart=pkg.group_restart))
            offset += len(pkg.components)
        return Supervisor("root", children, Strategy.ONE_FOR_ONE, self.options.max_restarts, self.options.max_seconds, on_event=self._record,
                          ledger=self.ledger)

    def _group_factory(self, pkg: Package, offset: int, name: str) -> Callable[[], Supervisor]:
        def make() -> Supervisor:
            specs = [self._component_spec(pkg, offset + i) for i in range(len(pkg.components))]
            p = pkg.policy
            return Supervisor(name, specs, p.strategy, p.max_restarts, p.max_seconds, on_event=self._record, ledger=self.ledger)

        return make

    def _component_spec(self, pkg: Package, index: int) -> ChildSpec:
        component = self.components[index]
        worker_cls = ProcessWorker if pkg.multiprocessing else ThreadWorker

        async def start() -> Any:
            return await worker_cls(self, index, component, pkg.activate).start()

        return ChildSpec(id=component.component_name, start=start, restart=pkg.policy.restart, shutdown=self.options.stop_timeout)

    def _record(self, event: dict[str, Any]) -> None:
        self.events.append(event)

    # ------------------------------------------------------------------ incarnations
    def incarnation_started(self, worker: Any) -> None:
        """``worker`` (a ProcessWorker or ThreadWorker) is now the one incarnation of its component."""
        self.incarnations[worker.name] = worker
        fallbacks = getattr(self, "fallbacks", None)
        if fallbacks is not None:
            fallbacks.incarnation_changed(worker.name)

    def incarnation_ended(self, worker: Any) -> None:
        name = worker.name
        if self.incarnations.get(name) is worker:
            del self.incarnations[name]
        pending = self._hellos.get((name, worker.pid))
        if pending is not None and pending[1] is worker:  # it died before saying hello: forget its wait
            del self._hellos[(name, worker.pid)]
        fallbacks = getattr(self, "fallbacks", None)
        if fallbacks is not None:
            fallbacks.incarnation_changed(name)

    def incarnation(self, name: str) -> Any | None:
        """The running incarnation of component ``name`` (from its spawn on), or None."""
        return self.incarnations.get(name)

    def summary(self) -> str:
        """What happened during the run, per component: restarts over the run and why."""
        lines = [f"EMOS run {self.ctx.run_id}: exit code {self.exit_code} ({self.exit_reason})"]
        for c in self.components:
            name = c.component_name
            entry = self.ledger.entry("worker", name)
            reasons = ", ".join(f"{n} {r}" for r, n in sorted(entry.reasons.items()))
            text = "restarted after: " + reasons if reasons else "no restarts"
            if entry.failed_starts:  # restart attempts (or the first start) that never came up
                text += f"; {entry.failed_starts} start(s) failed during start-up"
            lines.append(f"  {name:<24} {text}")
        for (kind, group), entry in sorted(self.ledger.entries.items()):
            if kind == "supervisor" and entry.reasons:
                lines.append(f"  group {group} restarted after: " + ", ".join(f"{n} {r}" for r, n in sorted(entry.reasons.items())))
        lines.extend(fallback_summary(self.events, self.components))
        escalations = [e for e in self.events if e["event"] == "escalated"]
        for e in escalations:
            lines.append(f"  escalation in {e['supervisor']}: {e.get('detail', '')}")
        return "\n".join(lines)

    # ------------------------------------------------------------------ control socket
    def expect_hello(self, name: str, pid: int | None = None) -> asyncio.Future[int]:
        """A future that the hello of component ``name`` from process ``pid`` completes (with
        the pid). ``pid`` defaults to that of the component's current incarnation: a worker
        registers itself (``incarnation_started``) just before it waits for its hello. Threaded
        incarnations share the launcher's pid, so for them the key is the name, as before."""
        owner = self.incarnations.get(name)
        if pid is None:
            pid = getattr(owner, "pid", None)
            if pid is None:
                raise ValueError(f"expect_hello: component {name!r} has no running incarnation to take the pid of; pass pid=")
        elif getattr(owner, "pid", None) != pid:
            owner = None
        fut: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self._hellos[(name, int(pid))] = (fut, owner)
        return fut

    def _control_ops(self) -> dict[str, Callable]:
        async def hello(req: dict, stream: Any) -> bool:
            name, pid = str(req.get("component")), req.get("pid")
            if isinstance(pid, bool) or not isinstance(pid, int):
                raise ValueError(f"hello from component {name!r}: 'pid' must be an int, got {pid!r}")
            waiting = self._hellos.pop((name, pid), None)
            if waiting is None or waiting[0].done():
                # A start that was abandoned (its group stopped or escalated) killed this process
                # already, or it is no process we started: its hello must not complete another start.
                self._stale_hellos.warning((name, pid), "supervisor: ignoring a hello from component %r pid %d: no start of that "
                                           "process is waiting for it (a stale incarnation?)", name, pid)
                return True
            waiting[0].set_result(pid)
            return True

        async def tree(req: dict, stream: Any) -> dict:
            assert self.root is not None
            return {"run_id": self.ctx.run_id, "pid": os.getpid(), "uptime_s": round(time.monotonic() - self.root.started_at, 3),
                    "up": self.up, "tree": self.fallbacks.annotate(self.root.tree()), "zygotes": self._zygote_pids()}

        async def events(req: dict, stream: Any) -> list:
            since = float(req.get("since", 0.0))
            return [e for e in self.events if e["t"] >= since]

        async def stop(req: dict, stream: Any) -> bool:
            self.request_stop(str(req.get("reason", "stopped through the control socket")))
            return True

        return {C.SUPERVISOR_HELLO: hello, C.SUPERVISOR_TREE: tree, C.SUPERVISOR_EVENTS: events, C.SUPERVISOR_STOP: stop, C.SUPERVISOR_LIFECYCLE: lifecycle_op(lambda: self.fallbacks)}


def find_runs() -> list[Path]:
    """Run directories of live systems of this user (newest first)."""
    from emos.transport.context import run_is_alive, runtime_root

    runs = [p for p in runtime_root().iterdir() if (p / "supervisor.sock").exists() and run_is_alive(p.name)]
    return sorted(runs, key=lambda p: p.stat().st_mtime, reverse=True)
