"""The Monitor: evaluates the recipe's events and runs their actions.

It is a supervised component like any other (``emos_monitor`` in ``emos status``): forked from the
zygote in multi-process mode (so it holds the recipe's functions and objects as the recipe built
them), a thread in threaded mode. It subscribes to exactly the topics the events and the action
bindings need (component status topics included when a condition reads them), keeps the latest
message of each on a :class:`~emos.events.event.Blackboard`, evaluates the events that read a
topic when a message arrives on it, and for each firing runs its actions in order, as one task:
two events firing at once run concurrently. Component actions go over the components' control
sockets and run inside them; recipe functions run in a worker thread here; lifecycle actions go to
the supervisor. An action that raises or times out is logged (event, action, component) and never
stops the Monitor. If the Monitor dies the supervisor restarts it; ``handle_once`` events that
fired are recorded in the run directory first, so they stay fired.
"""
from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import Collection
from typing import Any

from emos.core.component import BaseComponent
from emos.core.control import SUPERVISOR_LIFECYCLE, AsyncControlClient
from emos.core.priority import lower_priority
from emos.core.rpc import AsyncRpcClient
from emos.events.action import Action
from emos.events.event import Blackboard, Event, EventTracker
from emos.events.runner import ActionRuntime, prepare, run_action
from emos.events.topic_group import TopicEvents
from emos.io.topic import Topic
from emos.msgs.std import String
from emos.ratelimit import RateLimitedLog
from emos.supervisor.monitor_net import ActionRoutes, place_inputs

MONITOR_NAME = "emos_monitor"
# Each fired event's outcome (String, JSON), published when a Cortex monitors the run
# (``Launcher.add_pkg(monitor=cortex)``): ``{"event", "topic", "actions": [{"action", "ok", "detail"}]}``.
OUTCOMES_TOPIC = f"{MONITOR_NAME}/outcomes"


class Monitor(BaseComponent):
    # No spinning after a wake-up: the actions a message fires are sent on the next turn of the
    # event loop, which a spin would delay, and a spinning Monitor competes for the CPU with the
    # components it watches.
    _wake_spin_us = 0.0
    # Publishers wake the Monitor after the components that read the same message (waker.py).
    _wake_background = True

    def __init__(self, entries: list[tuple[Event, list[Action]]], action_timeout: float = 10.0, nice: int = 0,
                 local_components: Collection[str] = (), defer_ms: float = 0.0, report_outcomes: bool = False):
        self._entries = entries
        self._report_outcomes = report_outcomes
        self._defer_ms = defer_ms
        # Read by the node: after a wake-up, wait this long before reading (see Node._on_wake).
        self._wake_defer_s = defer_ms / 1000.0
        self._action_timeout = action_timeout
        self._nice = nice
        self._local_components = tuple(local_components)
        topics: dict[str, Topic] = {}
        outputs: dict[str, Topic] = {}
        for event, actions in entries:
            topics.update(event.topics)
            for a in actions:
                topics.update(a.bound_topics)
                if a.predefined == "publish_message":
                    topic = a.kwargs["topic"].value  # a Literal: the topic itself, not a binding
                    outputs[topic.name] = topic
        if report_outcomes:
            outputs[OUTCOMES_TOPIC] = self._outcomes = Topic(name=OUTCOMES_TOPIC, msg_type="String")
        # Component statuses: this run's from its rings, other runs' over Zenoh (across hosts).
        topics = place_inputs(topics, self._local_components)
        super().__init__(component_name=MONITOR_NAME, inputs=list(topics.values()), outputs=list(outputs.values()))
        if topics:
            self.trigger = list(topics.values())
        else:
            self.run_type = "Event"
        self._status_after_step = False  # a flood of event messages must not flood the status topic

    def __deepcopy__(self, memo: dict) -> Monitor:
        # Threaded mode restarts take a fresh copy: the definitions are shared, the state is not.
        return Monitor(self._entries, self._action_timeout, self._nice, self._local_components, self._defer_ms, self._report_outcomes)

    # -- lifecycle ------------------------------------------------------------------------------
    def custom_on_activate(self) -> None:
        # The Monitor wakes on the same messages as the components that read them; evaluating
        # many events per message must not delay those readers when the cores are short.
        lower_priority(self._nice, self.component_name)
        node = self.node
        self._fired_path = node.ctx.run_dir / "monitor_fired.json"
        fired = self._load_fired()
        self.board = Blackboard({t.name: t.data_timeout for t in self.in_topics})
        self.trackers = [EventTracker(e.to_dict(), fired_before=i in fired) for i, (e, _) in enumerate(self._entries)]
        by_topic: dict[str, list[int]] = {}
        for i, tr in enumerate(self.trackers):
            for t in tr.topics:
                by_topic.setdefault(t, []).append(i)
        self.by_topic = {t: TopicEvents(indices, self.trackers) for t, indices in by_topic.items()}
        self.runtime = MonitorRuntime(self)
        self._errors = RateLimitedLog(interval=5.0)  # logs to get_logger(), given per call
        self._tasks: set[asyncio.Task] = set()
        self.stats = {"fired": 0, "actions_ok": 0, "actions_failed": 0}
        self.get_logger().info("[%s] watching %d events on %d topics", self.component_name, len(self._entries), len(self.in_topics))

    def custom_on_deactivate(self) -> None:
        for task in list(self._tasks):
            task.cancel()
        self.runtime.cancel_periodic()
        self.runtime.routes.close()

    def _load_fired(self) -> set[int]:
        try:
            return set(json.loads(self._fired_path.read_text()))
        except FileNotFoundError:
            return set()
        except (OSError, ValueError) as exc:
            self.get_logger().error("[%s] cannot read %s (%s): handle_once events may fire again", self.component_name, self._fired_path, exc)
            return set()

    def _record_fired(self, index: int) -> None:
        fired = self._load_fired() | {index}
        tmp = self._fired_path.with_suffix(".tmp")
        tmp.write_text(json.dumps(sorted(fired)))
        os.replace(tmp, self._fired_path)

    # -- evaluation -----------------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        if topic is None:
            return
        now = time.monotonic()
        # Freshness counts from the publish stamp, not from our receipt: a message that waited in
        # a ring (a restarted Monitor reading old messages) must not pass for fresh data.
        stamp = self.node.trigger_stamp_ns
        age = (time.time_ns() - stamp) / 1e9 if stamp is not None else self.input_age(topic)
        self.board.put(topic.name, msg, now - age if age is not None and age > 0 else now)
        group = self.by_topic.get(topic.name)
        if group is None:
            return
        cache: dict[str, Any] = {}  # each topic's freshness is looked up once per message, not per leaf

        def fresh(name: str) -> Any:
            if name not in cache:
                cache[name] = self.board.fresh(name, now)
            return cache[name]

        try:
            # The fast path: every condition on this topic in one call, the ones that matter observed.
            firing = [i for i, value in group.values(fresh, topic.name) if self.trackers[i].observe(value, now)]
        except Exception:
            firing = None  # a condition raised: check the events one by one below, each error apart
        if firing is None:
            firing = self._check_each(group.indices, topic.name, now, fresh)
        else:
            firing += self._check_each(group.whole, topic.name, now, fresh)
        for i in sorted(firing):  # in the order the events were declared
            try:
                self._fire(i, topic.name, msg)
            except Exception as exc:  # binding its arguments or recording it failed: the others still fire
                self._event_error(i, topic.name, "fire", exc)
        self.health_status.set_healthy()

    def _check_each(self, indices: list[int], topic: str, now: float, fresh: Any) -> list[int]:
        """The events among ``indices`` that fire, checked one by one (an error stays with its event)."""
        firing = []
        for i in indices:
            try:
                if self.trackers[i].check(topic, self.board, now, fresh):
                    firing.append(i)
            except Exception as exc:  # one broken event must not stop the others (or restart us)
                self._event_error(i, topic, "evaluate", exc)
        return firing

    def _event_error(self, index: int, topic: str, stage: str, exc: Exception) -> None:
        self._errors.error((index, stage, type(exc).__name__), "[%s] event %r on %s: %s: %s", self.component_name,
                           self._entries[index][0], topic, type(exc).__name__, exc, logger=self.get_logger())

    def _fire(self, index: int, topic: str, msg: Any) -> None:
        event, actions = self._entries[index]
        if event.handle_once:
            self._record_fired(index)  # before acting: a Monitor killed mid-action must not fire it twice
        self.stats["fired"] += 1
        prepared = [prepare(a, self.board.latest) for a in actions]  # bindings resolve at fire time
        task = asyncio.ensure_future(self._run(index, actions, prepared, topic, msg))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _run(self, index: int, actions: list[Action], prepared: list, topic: str, msg: Any) -> None:
        event = self._entries[index][0]
        outcomes: list[dict] = []
        for k, (action, args) in enumerate(zip(actions, prepared)):
            try:
                # Every path of run_action has its own deadline (RPC, worker thread, service call),
                # so no extra wait_for task sits on the hot path of an event.
                await run_action(action, self.runtime, topic, msg, args)
                self.stats["actions_ok"] += 1
                outcomes.append({"action": action.describe(), "component": action.component, "ok": True})
            except asyncio.CancelledError:
                raise
            except BaseException as exc:
                self.stats["actions_failed"] += 1
                what = "timed out" if isinstance(exc, (asyncio.TimeoutError, TimeoutError)) and not str(exc) else f"failed: {type(exc).__name__}: {exc}"
                self._errors.error((index, k, type(exc).__name__), "[%s] event %r: action %d/%d %s (component %s) %s",
                                   self.component_name, event, k + 1, len(actions), action.describe(), action.component or "-",
                                   what, logger=self.get_logger())
                outcomes.append({"action": action.describe(), "component": action.component, "ok": False, "detail": what[:300]})
        if self._report_outcomes:
            try:
                self.publish(self._outcomes, String(data=json.dumps({"event": str(event)[:200], "topic": topic, "actions": outcomes}, default=str)))
            except Exception as exc:  # a report that cannot go out must not fail the event
                self._errors.error(("report", type(exc).__name__), "[%s] publishing the outcome of event %r on %s: %s",
                                   self.component_name, event, OUTCOMES_TOPIC, exc, logger=self.get_logger())

    def monitor_stats(self) -> dict:
        """Counts since this Monitor started (``emos component call emos_monitor execute_method``)."""
        return dict(self.stats, events=len(self._entries), fire_counts=[t.fire_count for t in self.trackers])


class MonitorRuntime(ActionRuntime):
    def __init__(self, monitor: Monitor):
        self.monitor = monitor
        self.ctx = monitor.node.ctx
        self.log = monitor.get_logger()
        self.timeout = monitor._action_timeout
        self.links = AsyncControlClient(self.ctx, queue_timeout=monitor._action_timeout)
        self.routes = ActionRoutes((*monitor._local_components, MONITOR_NAME), monitor._action_timeout)  # components of other runs

    async def call_component(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        if self.routes.is_remote(component):
            return await self.routes.control(component, op, payload, timeout)
        return await self.links.call(component, op, timeout, **payload)

    async def call_service(self, name: str, request: Any, response_type: type, component: str | None = None) -> Any:
        if component is not None and self.routes.is_remote(component):
            return await self.routes.call_service(component, name, request, response_type)
        return await super().call_service(name, request, response_type, component)

    async def send_goal(self, name: str, types: tuple, goal: Any, component: str | None = None) -> Any:
        if component is not None and self.routes.is_remote(component):
            return await self.routes.send_goal(component, name, goal)
        return await super().send_goal(name, types, goal, component)

    async def lifecycle(self, component: str, op: str, wait_time: float = 0.0) -> Any:
        if self.routes.is_remote(component):
            return await self.routes.lifecycle(component, op, wait_time)
        sock = self.monitor.node.supervisor_socket
        if not sock:
            raise RuntimeError("no supervisor to send the lifecycle request to")
        client = AsyncRpcClient(sock)
        try:
            return await client.call(SUPERVISOR_LIFECYCLE, component=component, request=op, wait_time=wait_time, by="event",
                                     timeout=self.timeout + wait_time + 30.0)
        finally:
            await client.close()

    def publish(self, topic: Topic, msg: Any) -> None:
        self.monitor.publish(topic, msg)

    def latest(self, topic: str) -> Any | None:
        return self.monitor.board.latest(topic)
