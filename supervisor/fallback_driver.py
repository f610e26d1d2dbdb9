"""Fallbacks, run by the supervisor from every component's status stream.

Division of labour with the supervision tree (see docs/runtime.md):

* a process **death** (or a missed heartbeat) is the tree's: restart strategy and intensity;
* a **reported** failure (the status a live component publishes) is the fallback ladder's.
  A ``restart`` on a ladder asks the tree to restart the child (``Supervisor.restart_child``), so
  it counts against the same intensity and a breach escalates as a crash would.

The ladder state (:class:`~emos.core.fallbacks.FallbackTracker`) lives here, not in the component:
it survives the restarts it causes, and behaves the same for threads and processes. A component
that gave up shows ``GAVE_UP`` as its health in ``emos status`` until it has been healthy again
for ``reset_after`` seconds.

A status belongs to one incarnation of its component. Only the running incarnation's count:
written by its process (the ring's writer pid) and stamped after it was spawned. When an
incarnation ends or a new one starts (a crash, a group restart), the failure the old one
reported is forgotten: the ladder waits for what the new one reports (its spent retries stay),
and a restart the ladder asked for the old one does not hit the new one.
"""
from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from emos.core import control as C
from emos.core.control import AsyncControlClient
from emos.core.fallbacks import HANDLERS, Fallback, FallbackTracker
from emos.core.health import HealthLevel
from emos.events.action import ActionError
from emos.events.runner import ActionRuntime, run_action
from emos.io.topic import Topic
from emos.msgs import codec
from emos.msgs.status import ComponentStatus
from emos.ratelimit import RateLimitedLog
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker

from .sim_pacing import SimPacer
from .tree import FALLBACK

if TYPE_CHECKING:
    from emos.supervisor.orchestration import Orchestration
    from emos.supervisor.system import System

log = logging.getLogger("emos.fallbacks")


class FallbackDriver(ActionRuntime):
    def __init__(self, system: System, orchestration: Orchestration, root: Callable[[], Any]):
        from emos import actions as A

        self.system = system
        self.ctx = system.ctx
        self.log = log
        self.timeout = orchestration.action_timeout
        self._root = root
        self.loop = asyncio.get_running_loop()
        self.links = AsyncControlClient(self.ctx, queue_timeout=orchestration.action_timeout)
        self.trackers: dict[str, FallbackTracker] = {}
        self.giveups: dict[str, Fallback | None] = {}
        self.last_status: dict[str, ComponentStatus] = {}
        self._not_before: dict[str, float] = {}  # wall time; statuses stamped earlier belong to a past incarnation
        self._status_of: dict[str, Any] = {}  # name -> the incarnation whose status the tracker holds
        self._tasks: dict[str, asyncio.Task] = {}
        # name -> (wall time, event): set by the first status stamped after that time
        self._fresh: dict[str, tuple[float, asyncio.Event]] = {}
        self._publishers: dict[str, Publisher] = {}
        self._errors = RateLimitedLog(log, interval=5.0)
        self.waker = Waker(self.ctx)
        self.loop.add_reader(self.waker.fd, self._on_wake)
        self.subs: dict[str, Subscriber] = {}
        for comp in system.components:
            name = comp.component_name
            own = comp.fallbacks
            handlers = orchestration.handlers_for(comp)
            # launcher.fallback_rate paces the launcher-wide policies (and the default restart);
            # a component's own handlers keep its config.fallback_rate.
            own_handlers = any(k in own for k in HANDLERS)
            rate = comp.config.fallback_rate if own_handlers or not orchestration.fallback_rate else orchestration.fallback_rate
            self.trackers[name] = FallbackTracker(handlers, own.get("on_giveup"), Fallback(A.restart(component=comp), None, f"{name} default"),
                                                  rate, reset_after=orchestration.reset_after)
            self.subs[name] = Subscriber(self.ctx, comp.status_topic.name, ComponentStatus, waker=self.waker, queue_size=4)
        # Ladders of components on simulated time wait for that clock too (emos.supervisor.sim_pacing).
        self._sim_paced = {c.component_name for c in system.components if getattr(c.config, "use_sim_time", False)}
        self._pacer = SimPacer(self.ctx) if self._sim_paced else None
        self._poll = asyncio.ensure_future(self._poll_loop())
        self._closed = False

    # -- status intake --------------------------------------------------------------------------
    def _on_wake(self) -> None:
        self.waker.drain()
        for name, sub in self.subs.items():
            # Only the component's own status ring counts (its publisher id is its name): a
            # stray publisher on <name>/status must not drive its fallbacks.
            # (take_raw reads every ring of the topic: a damaged or forged one is dropped and logged.)
            items = [item for item in sub.take_raw() if item[2] == name]
            if not items:
                continue
            own = sub.sources.get(name)
            incarnation = self.system.incarnation(name)
            if incarnation is None or own is None or own.ring.writer_pid != incarnation.pid:
                continue  # between incarnations, or not written by the running one
            try:
                status = codec.decode(ComponentStatus, items[-1][1], copy=True)
            except Exception as exc:
                self._report(name, "status decode", exc)
                continue
            stamp = status.header.stamp.to_sec()
            if stamp < self._not_before.get(name, 0.0) or stamp < incarnation.started_wall:
                continue  # reported by an earlier incarnation
            self._status_of[name] = incarnation
            self.last_status[name] = status
            waiting = self._fresh.get(name)
            if waiting is not None and status.header.stamp.to_sec() >= waiting[0]:
                del self._fresh[name]
                waiting[1].set()
            tracker = self.trackers[name]
            tracker.observe(status.status)
            if tracker.failing and not tracker.gave_up and name not in self._tasks:
                self._tasks[name] = asyncio.ensure_future(self._ladder(name))

    async def _poll_loop(self) -> None:
        while True:  # a lost wake-up (full FIFO) must not stall a ladder; healthy timers need ticks too
            await asyncio.sleep(0.1)
            self._on_wake()
            if self._pacer is not None:
                self._pacer.now()  # subscribed to /clock before a ladder needs it (a new reader sees only later ticks)

    async def _ladder(self, name: str) -> None:
        tracker = self.trackers[name]
        try:
            while tracker.failing and not tracker.gave_up:
                wait = tracker.wait_s()
                if wait > 0:
                    await asyncio.sleep(wait)
                    continue
                decision = tracker.next()
                if decision is None:
                    return
                if decision["kind"] == "giveup":
                    await self._give_up(name, decision)
                    return
                action = decision["action"]
                of = decision["of"]
                sim_at = self._pacer.now() if self._pacer is not None and name in self._sim_paced else None
                self._record(name, "fallback", handler=decision["handler"], action=action.describe(), step=decision["step"] + 1,
                             steps=decision["steps"], attempt=decision["try"], of=of if of is not None else "unlimited",
                             level=tracker.level.name, **({} if sim_at is None else {"sim_time": round(sim_at, 2)}))
                # Judge an action on this component by the status it publishes afterwards (a
                # component action publishes one when it returns; a restarted one at start-up),
                # not by the failure that was already on the stream.
                on_self = action.component == name
                restarting = on_self and action.kind == "lifecycle" and action.kwargs.get("op") == "restart"
                fresh = asyncio.Event()
                if on_self:
                    self._fresh[name] = (time.time(), fresh)
                try:
                    result = await asyncio.wait_for(run_action(action, self), self.timeout + 30.0)
                    if result is True and not restarting:
                        log.info("[%s] fallback %s reports recovery", name, action.describe())
                    # The outcome, for a monitor that watches the run (a Cortex reads the events).
                    self._record(name, "fallback_result", action=action.describe(), ok=result is not False)
                    if on_self:
                        await asyncio.wait_for(fresh.wait(), self.timeout if restarting else 1.0)
                except Exception as exc:
                    self._report(name, action.describe(), exc)
                    self._record(name, "fallback_result", action=action.describe(), ok=False, detail=f"{type(exc).__name__}: {exc}"[:300])
                finally:
                    self._fresh.pop(name, None)
                await asyncio.sleep(tracker.period)
                if sim_at is not None and self._pacer is not None:
                    # A step on simulated time gets its period on that clock as well: a loaded
                    # machine slows the simulator, and the next step must not come before this
                    # one has had its simulated second to act (a back-out driven, a re-plan followed).
                    await self._pacer.wait_until(sim_at, tracker.period, f"[{name}] fallback ladder")
        finally:
            self._tasks.pop(name, None)

    async def _give_up(self, name: str, decision: dict) -> None:
        tracker = self.trackers[name]
        self._record(name, "gave_up", handler=decision["handler"], level=tracker.level.name)
        log.error("[%s] fallbacks exhausted (%s, %s): giving up%s", name, decision["handler"], tracker.level.name,
                  "; running on_giveup" if decision["actions"] else "")
        for action in decision["actions"]:
            try:
                await asyncio.wait_for(run_action(action, self), self.timeout + 30.0)
            except Exception as exc:
                self._report(name, f"on_giveup {action.describe()}", exc)

    def incarnation_changed(self, name: str) -> None:
        """An incarnation of ``name`` ended or started: the failure the tracker holds was
        reported by one that is gone, so no ladder acts on it (a running ladder stops after its
        current step). What the new incarnation reports decides. Spent retries are kept: they
        reset only after ``reset_after`` seconds of health."""
        tracker = self.trackers.get(name)
        if tracker is None or self._status_of.get(name) is self.system.incarnation(name):
            return
        tracker.level = HealthLevel.HEALTHY
        tracker.failing_since = None
        self.last_status.pop(name, None)

    def _report(self, name: str, what: str, exc: BaseException) -> None:
        self._errors.error((name, what, type(exc).__name__), "[%s] fallback action %s failed: %s: %s", name, what, type(exc).__name__, exc)

    def _record(self, name: str, event: str, **extra: Any) -> None:
        self.system._record({"t": time.monotonic(), "wall": time.time(), "supervisor": "fallbacks", "child": name, "event": event, **extra})
        log.info("[%s] %s %s", name, event, " ".join(f"{k}={v}" for k, v in extra.items()))

    # -- ActionRuntime --------------------------------------------------------------------------
    async def call_component(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        return await self.links.call(component, op, timeout, **payload)

    async def lifecycle(self, component: str, op: str, wait_time: float = 0.0, why: str = FALLBACK, by: str = "") -> Any:
        """start / stop (lifecycle transitions) or restart (through the supervision tree).

        ``why``: ``FALLBACK`` when a ladder of this driver asks (run_action calls this with the
        defaults), ``REQUESTED`` through the supervisor socket (``by`` says who, if told)."""
        if op in ("start", "stop"):
            return await self.links.call(component, C.TRANSITION, self.timeout, transition="activate" if op == "start" else "deactivate")
        if op != "restart":
            raise ActionError(f"unknown lifecycle operation {op!r} (start, stop, restart)")
        # The incarnation to restart: for a ladder's own component, the one whose failure it
        # judged; else the one running now. None (between incarnations): the next one to run.
        target = self._status_of.get(component) if why == FALLBACK and component in self._tasks else self.system.incarnation(component)
        detail = f"restart of {component} requested by {'a fallback' if why == FALLBACK else by or 'a request'}"
        deadline = time.monotonic() + self.timeout
        while True:
            if target is not None and self.system.incarnation(component) is not target:
                log.info("[%s] restart skipped: the incarnation it was for (pid %s) has ended already", component, target.pid)
                return True
            root = self._root()
            sup = root.find(component) if root is not None else None
            if sup is not None:
                self._not_before[component] = time.time()
                if await sup.restart_child(component, reason="restart_requested", detail=detail, wait_time=wait_time, why=why, only_if=target):
                    return True
            if time.monotonic() >= deadline:
                raise ActionError(f"cannot restart {component!r}: it is not running (stopping, or its group is being restarted)")
            await asyncio.sleep(0.05)

    def publish(self, topic: Topic, msg: Any) -> None:
        pub = self._publishers.get(topic.name)
        if pub is None:
            pub = self._publishers[topic.name] = Publisher(self.ctx, topic.name, topic.msg_type, publisher_id="emos_fallbacks", depth=topic.qos_profile.queue_size)
        pub.publish(msg)

    def latest(self, topic: str) -> Any | None:
        return None  # fallback actions take static arguments (bindings are for events)

    # -- reporting ------------------------------------------------------------------------------
    def annotate(self, tree: dict) -> dict:
        """Mark components that gave up in a ``tree`` answer (``emos status``)."""
        if tree.get("kind") == "worker":
            tracker = self.trackers.get(tree.get("name", ""))
            if tracker is not None:
                tree["fallback_attempts"] = tracker.attempts
                if tracker.gave_up:
                    tree["fallback"] = f"gave up ({tracker.gave_up_on} on {tracker.level.name})"
                    tree["health"] = "GAVE_UP"
        for child in tree.get("children", []):
            self.annotate(child)
        return tree

    def gave_up(self) -> list[str]:
        return [n for n, t in self.trackers.items() if t.gave_up]

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._poll.cancel()
        for task in list(self._tasks.values()):
            task.cancel()
        self.cancel_periodic()
        self.loop.remove_reader(self.waker.fd)
        for sub in self.subs.values():
            sub.close()
        for pub in self._publishers.values():
            pub.close()
        self.waker.close()
        await self.links.close()
