"""Erlang/OTP supervision: strategies, restart types, restart intensity and escalation.

A :class:`Supervisor` starts its children in order and stops them in reverse order. When a
child exits it decides, by the child's restart type, whether to restart:

* ``permanent``: always; ``transient``: only after an abnormal exit; ``temporary``: never.

and, by its strategy, what to restart:

* ``one_for_one``: just that child;
* ``one_for_all``: every child (the others are stopped first, in reverse order);
* ``rest_for_one``: that child and the ones started after it.

More than ``max_restarts`` restarts within ``max_seconds`` breaches the restart intensity: the
supervisor stops all its children and exits itself with reason ``escalated``, and its own
supervisor handles that like any child exit. At the root, that ends the system.

Children are anything with an ``exited`` future and an async ``stop(timeout)``: a component
process, a component thread, or another Supervisor.

Every start of every child is written in a :class:`RestartLedger` that the whole tree shares and
that outlives group incarnations (a group restarted by its parent is a new Supervisor): a
component's restarts are counted over the run, each with its reason.
"""
from __future__ import annotations

import asyncio
import collections
import contextvars
import logging
import time
from collections.abc import Awaitable, Callable
from enum import Enum
from typing import Any, Protocol

from attrs import define, field

from emos.errors import EmosError

log = logging.getLogger("emos.supervisor")


class Strategy(str, Enum):
    ONE_FOR_ONE = "one_for_one"
    ONE_FOR_ALL = "one_for_all"
    REST_FOR_ONE = "rest_for_one"


class RestartType(str, Enum):
    PERMANENT = "permanent"
    TRANSIENT = "transient"
    TEMPORARY = "temporary"


@define
class Exit:
    """Why a child stopped. ``reason``: normal, crash, killed, hang, shutdown, escalated, start_failed."""

    reason: str
    detail: str = ""
    at: float = field(factory=time.monotonic)

    @property
    def abnormal(self) -> bool:
        return self.reason not in ("normal", "shutdown")


class Child(Protocol):
    @property
    def exited(self) -> asyncio.Future[Exit]: ...

    async def stop(self, timeout: float) -> Exit: ...

    def info(self) -> dict[str, Any]: ...


@define
class ChildSpec:
    id: str
    start: Callable[[], Awaitable[Child]]
    restart: RestartType = field(default=RestartType.PERMANENT, converter=RestartType)
    shutdown: float = 5.0  # seconds between the polite stop and SIGKILL
    kind: str = "worker"


class StartFailed(EmosError, RuntimeError):
    pass


class StartCancelled(StartFailed):
    """A child's start was abandoned because its group is stopping or escalating; the start's
    own clean-up (a worker kills and reaps the process it spawned) has run by then."""


# Why a child is (re)started. A child's own exit reasons (crash, killed, hang, normal, start_failed,
# escalated for a group) restart it under that name; besides them:
FALLBACK = "fallback"  # a fallback ladder restarted it (its status reported a failure)
REQUESTED = "requested"  # someone asked: the CLI, the web UI, an event's action, the component itself
GROUP_RESTART = "group restart"  # a sibling failed and the strategy (one_for_all, rest_for_one) took it along
ESCALATION = "escalation"  # its group breached its restart intensity and was restarted by its parent

# The reason a (sub-)supervisor is being started for, seen by its Supervisor.start().
_GROUP_START_REASON: contextvars.ContextVar[str | None] = contextvars.ContextVar("emos_group_start_reason", default=None)


@define
class LedgerEntry:
    starts: int = 0
    reasons: collections.Counter = field(factory=collections.Counter)  # restart reason -> count
    last_reason: str | None = None
    last_detail: str = ""
    last_at: float | None = None  # wall time of the last restart
    failed_starts: int = 0


class RestartLedger:
    """Starts per child over the whole run, across incarnations of their groups, by reason."""

    def __init__(self) -> None:
        self.entries: dict[tuple[str, str], LedgerEntry] = {}

    def entry(self, kind: str, cid: str) -> LedgerEntry:
        return self.entries.setdefault((kind, cid), LedgerEntry())

    def started(self, kind: str, cid: str, reason: str | None, detail: str = "") -> int:
        """Note a start; every start after the first is a restart. Returns the restarts so far."""
        e = self.entry(kind, cid)
        e.starts += 1
        if e.starts > 1:
            e.reasons[reason or "restart"] += 1
            e.last_reason, e.last_detail, e.last_at = reason or "restart", detail, time.time()
        return max(0, e.starts - 1)

    def start_failed(self, kind: str, cid: str) -> None:
        self.entry(kind, cid).failed_starts += 1

    def restarts(self, kind: str, cid: str) -> int:
        e = self.entries.get((kind, cid))
        return max(0, e.starts - 1) if e is not None else 0

    def info(self, kind: str, cid: str) -> dict[str, Any]:
        """What ``emos status`` shows of a child's restarts."""
        e = self.entries.get((kind, cid)) or LedgerEntry()
        out: dict[str, Any] = {"restarts": max(0, e.starts - 1), "restart_reasons": dict(sorted(e.reasons.items())),
                               "last_restart_reason": e.last_reason}
        if e.last_detail:
            out["last_restart_detail"] = e.last_detail
        if e.failed_starts:
            out["failed_starts"] = e.failed_starts
        return out


EventSink = Callable[[dict[str, Any]], None]


class Supervisor:
    def __init__(
        self,
        name: str,
        children: list[ChildSpec],
        strategy: Strategy | str = Strategy.ONE_FOR_ONE,
        max_restarts: int = 5,
        max_seconds: float = 10.0,
        on_event: EventSink | None = None,
        ledger: RestartLedger | None = None,
    ):
        if max_restarts < 0 or max_seconds <= 0:
            raise ValueError(f"supervisor {name!r}: max_restarts must be >= 0 and max_seconds > 0")
        ids = [c.id for c in children]
        if len(set(ids)) != len(ids):
            raise ValueError(f"supervisor {name!r}: duplicate child ids in {ids}")
        self.name = name
        self.specs: list[ChildSpec] = list(children)
        self.strategy = Strategy(strategy)
        self.max_restarts = max_restarts
        self.max_seconds = max_seconds
        self.on_event = on_event
        self.running: dict[str, Child] = {}
        self.ledger = ledger if ledger is not None else RestartLedger()
        self._restarts: collections.deque[float] = collections.deque()
        self._lock: asyncio.Lock | None = None
        # one_for_one restarts touch one child each, so each takes only that child's lock: a
        # SIGTERM-deaf child being stopped for up to its shutdown time must not hold up the
        # restart of a sibling that died meanwhile. The other strategies take the group's lock.
        self._child_locks: dict[str, asyncio.Lock] = {}
        self._stopping = False
        self._watchers: dict[str, asyncio.Task] = {}
        # Starts in progress (child id -> the task running its spec.start()). They are part of
        # the group's state: a child still waiting for its hello is not in ``running`` yet, and
        # a stop or an escalation that skipped it would leave it alive next to the copy the
        # parent starts when it restarts the group. Stopping and escalating cancel them.
        self._starting: dict[str, asyncio.Task] = {}
        self._exited: asyncio.Future[Exit] | None = None  # made by start(), on the running loop
        self.started_at = 0.0

    @property
    def exited(self) -> asyncio.Future[Exit]:
        """Resolves with the supervisor's own Exit (shutdown or escalated); exists once started."""
        if self._exited is None:
            raise RuntimeError(f"supervisor {self.name!r} has not been started: it has no exit yet")
        return self._exited

    # ------------------------------------------------------------------ events
    def _emit(self, event: str, child: str = "", **extra: Any) -> None:
        record = {"t": time.monotonic(), "wall": time.time(), "supervisor": self.name, "child": child, "event": event, **extra}
        if event in ("exit", "escalated", "start_failed"):
            log.warning("[%s] %s %s %s", self.name, child, event, extra.get("detail", ""))
        else:
            log.info("[%s] %s %s %s", self.name, child, event, extra.get("detail", ""))
        if self.on_event is not None:
            self.on_event(record)

    # ------------------------------------------------------------------ start / stop
    async def start(self) -> Supervisor:
        loop = asyncio.get_running_loop()
        self._lock = asyncio.Lock()
        self._exited = loop.create_future()
        self._stopping = False
        self.started_at = time.monotonic()
        # A group started again by its parent starts each child again: that is their restart too.
        group_reason = _GROUP_START_REASON.get()
        reason = None if group_reason is None else GROUP_RESTART if group_reason == GROUP_RESTART else ESCALATION
        detail = "" if group_reason is None else f"group {self.name} restarted ({group_reason})"
        started: list[str] = []
        for spec in self.specs:
            if self._stopping:
                break  # a child that died meanwhile escalated: our exit says so, our escalation stopped the rest
            try:
                await self._start_child(spec, reason, detail)
            except StartCancelled:
                break  # the same escalation cancelled this start
            except asyncio.CancelledError:
                # Our own start was cancelled (our parent is stopping or escalating): take down
                # what we started and what is still starting, then let the cancellation through.
                self._stopping = True
                await self._cancel_starts()
                for cid in reversed([s.id for s in self.specs if s.id in self.running]):
                    await self._stop_child(cid)
                raise
            except Exception as exc:
                self.ledger.start_failed(spec.kind, spec.id)
                self._emit("start_failed", spec.id, detail=str(exc))
                for cid in reversed(started):
                    await self._stop_child(cid)
                raise StartFailed(f"supervisor {self.name!r}: child {spec.id!r} failed to start: {exc}") from exc
            started.append(spec.id)
        return self

    async def _start_child(self, spec: ChildSpec, reason: str | None = None, detail: str = "") -> int:
        """Start ``spec`` (``reason``: why, None for its first start); returns its restarts so far.

        Raises StartCancelled if the group stops or escalates before the child is up (or has
        already begun to); the start runs as a task of its own, kept in ``_starting``, so that
        ``_cancel_starts`` can end it without cancelling whoever asked for the start."""
        if self._stopping:
            raise StartCancelled(f"supervisor {self.name!r}: not starting {spec.id!r}: the group is stopping")
        token = _GROUP_START_REASON.set(reason)  # seen by a sub-supervisor's start() (the task copies the context)
        try:
            task = asyncio.ensure_future(self._run_start(spec, reason, detail))
        finally:
            _GROUP_START_REASON.reset(token)
        self._starting[spec.id] = task
        try:
            return await task
        except asyncio.CancelledError:
            me = asyncio.current_task()
            if not task.cancelled() or (me is not None and me.cancelling()):
                raise  # we are being cancelled ourselves: the start went with us
            log.warning("[%s] start of %s abandoned: the group is stopping or escalating (what it spawned is killed and reaped)",
                        self.name, spec.id)
            raise StartCancelled(f"supervisor {self.name!r}: start of {spec.id!r} cancelled: the group is stopping") from None
        finally:
            if self._starting.get(spec.id) is task:
                del self._starting[spec.id]

    async def _run_start(self, spec: ChildSpec, reason: str | None, detail: str) -> int:
        child = await spec.start()
        # No await from here on: once the task is done the child is in ``running`` (and so
        # stopped by a stop or an escalation), never in neither place.
        self.running[spec.id] = child
        self._watchers[spec.id] = asyncio.ensure_future(self._watch(spec.id, child))
        restarts = self.ledger.started(spec.kind, spec.id, reason, detail)
        self._emit("started", spec.id, **{k: v for k, v in child.info().items() if k in ("pid",)})
        return restarts

    async def _watch(self, cid: str, child: Child) -> None:
        try:
            result = await asyncio.shield(child.exited)
        except asyncio.CancelledError:
            return
        await self._on_exit(cid, child, result)

    def _restart_lock(self, cid: str) -> asyncio.Lock:
        """The lock a restart of ``cid`` holds: the child's own under one_for_one, else the group's."""
        assert self._lock is not None
        if self.strategy != Strategy.ONE_FOR_ONE:
            return self._lock
        return self._child_locks.setdefault(cid, asyncio.Lock())

    async def stop(self, timeout: float | None = None) -> Exit:
        """Stop every child in reverse start order, then finish with reason ``shutdown``."""
        assert self._lock is not None  # made by start()
        self._stopping = True
        await self._cancel_starts()  # before the locks: a restart holding one may be waiting for a hello
        async with self._lock:
            for spec in reversed(self.specs):
                if self.strategy == Strategy.ONE_FOR_ONE:
                    async with self._restart_lock(spec.id):  # a restart of it in flight finishes first
                        if spec.id in self.running:
                            await self._stop_child(spec.id)
                elif spec.id in self.running:
                    await self._stop_child(spec.id)
        if not self.exited.done():
            self.exited.set_result(Exit("shutdown", f"supervisor {self.name} stopped"))
        return self.exited.result()

    async def _stop_child(self, cid: str) -> Exit | None:
        child = self.running.pop(cid, None)
        watcher = self._watchers.pop(cid, None)
        if watcher is not None:
            watcher.cancel()
        if child is None:
            return None
        spec = self._spec(cid)
        result = await child.stop(spec.shutdown if spec else 5.0)
        self._emit("stopped", cid, detail=result.detail or result.reason)
        return result

    async def _cancel_starts(self) -> None:
        """Cancel every start in progress and wait until each has cleaned up after itself (a
        worker kills and reaps the process it spawned; a sub-group stops what it started), so
        that nothing of this incarnation of the group outlives its stop or escalation."""
        me = asyncio.current_task()
        tasks = [t for t in self._starting.values() if t is not me and not t.done()]
        for t in tasks:
            t.cancel()
        if tasks:
            await asyncio.wait(tasks)

    def _spec(self, cid: str) -> ChildSpec | None:
        return next((s for s in self.specs if s.id == cid), None)

    # ------------------------------------------------------------------ restarts
    async def _on_exit(self, cid: str, child: Child, result: Exit) -> None:
        async with self._restart_lock(cid):
            if self._stopping or self.running.get(cid) is not child:
                return  # we stopped it ourselves (shutdown or strategy), or it was replaced
            del self.running[cid]
            self._watchers.pop(cid, None)
            self._emit("exit", cid, reason=result.reason, detail=result.detail, detected_at=result.at)
            spec = self._spec(cid)
            if spec is None:
                return
            if spec.restart == RestartType.TEMPORARY or (spec.restart == RestartType.TRANSIENT and not result.abnormal):
                if spec.restart == RestartType.TEMPORARY:
                    self.specs.remove(spec)
                return
            await self._restart_from(spec, result.reason, f"{cid}: {result.detail}" if result.detail else cid)

    async def restart_child(self, cid: str, reason: str, detail: str = "", wait_time: float = 0.0, why: str = REQUESTED,
                            only_if: Any = None) -> bool:
        """Restart a running child on request, exactly as if it had exited: same strategy,
        counted against the restart intensity (a breach escalates). ``reason`` names the exit
        event; ``why`` is the restart's reason in the ledger (``FALLBACK`` or ``REQUESTED``).
        ``only_if``: restart only that incarnation of the child. Returns False if the child is
        not running here (stopping, being restarted already, or another incarnation)."""
        async with self._restart_lock(cid):
            child = self.running.get(cid)
            spec = self._spec(cid)
            if self._stopping or child is None or spec is None or (only_if is not None and child is not only_if):
                return False
            await self._stop_child(cid)
            detail = detail or f"restart requested ({reason})"
            self._emit("exit", cid, reason=reason, by=why, detail=detail, detected_at=time.monotonic())
            if wait_time > 0:
                await asyncio.sleep(wait_time)
            await self._restart_from(spec, why, detail)
            return True

    def find(self, cid: str) -> Supervisor | None:
        """The (sub-)supervisor whose child ``cid`` is, searching running groups."""
        if any(s.id == cid for s in self.specs) and not isinstance(self.running.get(cid), Supervisor):
            return self
        for child in list(self.running.values()):
            if isinstance(child, Supervisor):
                found = child.find(cid)
                if found is not None:
                    return found
        return None

    def _intensity_ok(self) -> bool:
        now = time.monotonic()
        self._restarts.append(now)
        while self._restarts and now - self._restarts[0] > self.max_seconds:
            self._restarts.popleft()
        return len(self._restarts) <= self.max_restarts

    async def _restart_from(self, failed: ChildSpec, why: str, detail: str = "") -> None:
        """Restart ``failed`` (for ``why``) and, by the strategy, its siblings (a group restart)."""
        idx = self.specs.index(failed)
        if self.strategy == Strategy.ONE_FOR_ONE:
            group = [failed]
        elif self.strategy == Strategy.ONE_FOR_ALL:
            group = list(self.specs)
        else:
            group = self.specs[idx:]
        # Stop the others of the group in reverse order before restarting all of it in order.
        for spec in reversed(group):
            if spec.id in self.running:
                await self._stop_child(spec.id)
        for spec in group:
            while True:
                if not self._intensity_ok():
                    await self._escalate(f"more than {self.max_restarts} restarts in {self.max_seconds:g} s (last: {failed.id})")
                    return
                if self._stopping:
                    return  # the group is being stopped or escalated meanwhile (see _restart_lock)
                reason = why if spec is failed else GROUP_RESTART
                because = detail if spec is failed else f"after {failed.id} ({why})"
                try:
                    count = await self._start_child(spec, reason, because)
                    if self._stopping:  # escalated by a sibling while this one was starting
                        await self._stop_child(spec.id)
                        return
                    self._emit("restarted", spec.id, count=count, why=reason)
                    break
                except StartCancelled:
                    return  # a sibling escalated (or the group is stopping) while this one was starting
                except Exception as exc:
                    self.ledger.start_failed(spec.kind, spec.id)
                    self._emit("start_failed", spec.id, detail=str(exc))
                    await asyncio.sleep(0.05)  # counted against intensity; avoid a hot loop

    async def _escalate(self, why: str) -> None:
        self._stopping = True
        self._emit("escalated", detail=why)
        await self._cancel_starts()  # a child still starting is ours too: no copy of it may outlive us
        for spec in reversed(self.specs):
            if spec.id in self.running:
                await self._stop_child(spec.id)
        if not self.exited.done():
            self.exited.set_result(Exit("escalated", f"supervisor {self.name}: {why}"))

    # ------------------------------------------------------------------ introspection
    def info(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": "supervisor",
            "strategy": self.strategy.value,
            "intensity": f"{self.max_restarts}/{self.max_seconds:g}s",
            # over the run: restarts of its children (sub-groups: their own), whatever incarnation of it ran them
            "restarts": sum(self.ledger.restarts(s.kind, s.id) for s in self.specs),
        }

    def tree(self) -> dict[str, Any]:
        node = self.info()
        node["children"] = []
        for spec in self.specs:
            child = self.running.get(spec.id)
            if isinstance(child, Supervisor):
                entry = child.tree()
            elif child is not None:
                entry = child.info()
            else:
                entry = {"name": spec.id, "kind": spec.kind, "state": "stopped"}
            entry.setdefault("name", spec.id)
            entry["restart"] = spec.restart.value
            ledger = self.ledger.info(spec.kind, spec.id)
            if isinstance(child, Supervisor):  # its children's restarts and its own
                ledger["restarts"] += entry.get("restarts", 0)
            entry.update(ledger)
            node["children"].append(entry)
        return node


def supervisor_spec(sup_factory: Callable[[], Supervisor], sid: str, restart: RestartType | str = RestartType.PERMANENT, shutdown: float = 30.0) -> ChildSpec:
    """A ChildSpec whose child is a (sub-)supervisor built fresh at every start."""

    async def start() -> Child:
        return await sup_factory().start()

    return ChildSpec(id=sid, start=start, restart=RestartType(restart), shutdown=shutdown, kind="supervisor")
