"""The runtime of one component: its event loop, topics, status heartbeat and lifecycle.

A Node runs the same way in its own process and in a thread of the launcher (threaded mode):
one uvloop event loop, one wake-up FIFO for all its subscriptions, a control socket
``<run>/ctl/<component>.sock`` for lifecycle and parameter requests (its operations, path and
clients: :mod:`emos.core.control`), and a status publisher on ``<component>/status`` that is
both the health report and the supervisor's heartbeat.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
import operator
import os
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

from emos.config.base import ComponentRunType
from emos.core import control as C
from emos.core import lifecycle as L
from emos.core.clock import Pacer, SimTimeDriver, SimTimer
from emos.core.component import BaseComponent
from emos.core.control import control_socket
from emos.core.faults import PublishFaults, fault_ops
from emos.core.reconfig import reconfig_ops
from emos.core.rpc import CONTROL_FRAME, AsyncRpcClient, RpcServer
from emos.core.services import ActionServer, ServiceServer, describe_interfaces
from emos.io.topic import Topic, normalize_topic_name
from emos.msgs.status import ComponentStatus
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext, current
from emos.transport.pubsub import Publisher
from emos.transport.select import TopicPublisher, TopicSubscriber, open_publisher, open_server_bridge, open_subscriber, payload_decoder
from emos.transport.waker import DEFAULT_SPIN_US, Waker

ENV_SUPERVISOR_SOCKET = "EMOS_SUPERVISOR_SOCKET"
ENV_WAKE_SPIN_US = "EMOS_WAKE_SPIN_US"

__all__ = ["Node", "control_socket", "process_alive", "wake_spin_setting", "ENV_SUPERVISOR_SOCKET", "ENV_WAKE_SPIN_US"]


_STAMP_THEN_ORDER = operator.itemgetter(0, 1)  # a backlog item: (stamp, order read, input, payload)
_NO_INPUT = object()  # Node._run_step without a triggering message (a timer's step)


class _Input:
    __slots__ = ("topic", "sub", "raw", "stamp_ns", "decoded", "received_ns", "decode", "sim_at", "cache")

    def __init__(self, topic: Topic, sub: TopicSubscriber):
        self.topic, self.sub = topic, sub
        self.decode = payload_decoder(sub, topic.msg_type)  # a ring's payload -> its message (network ones come decoded)
        # The latest payload as take_raw gives it: a ring's read-only buffer, or a network
        # subscriber's decoded message (see TopicSubscriber.take_raw); None before the first.
        self.raw: Any = None
        self.stamp_ns = 0
        self.received_ns = 0
        self.decoded: Any = None
        self.sim_at: float | None = None  # simulated time it was taken at (a node on sim time)
        self.cache: deque[Any] | None = None  # the newest messages, decoded, when the component asked (Node.cache_input)


def wake_spin_setting() -> float:
    """Microseconds a node spins for more messages after a wake-up: ``$EMOS_WAKE_SPIN_US`` or the default."""
    raw = os.environ.get(ENV_WAKE_SPIN_US)
    if raw is None:
        return DEFAULT_SPIN_US
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"${ENV_WAKE_SPIN_US} must be a number of microseconds, got {raw!r}") from None
    if value < 0:
        raise ValueError(f"${ENV_WAKE_SPIN_US} must be >= 0 microseconds, got {raw!r}")
    return value


def process_alive(pid: int) -> bool:
    """True while ``pid`` runs; a killed process that is not reaped yet (a zombie) is dead."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rsplit(b")", 1)[-1].split()[0]
        return state not in (b"Z", b"X")
    except FileNotFoundError:
        return False
    except (OSError, IndexError):  # no /proc: ask the kernel (zombies then count as alive)
        try:
            os.kill(pid, 0)
            return True
        except ProcessLookupError:
            return False
        except PermissionError:
            return True


class Node:
    def __init__(self, component: BaseComponent, ctx: RunContext | None = None, supervisor_socket: str | None = None, wake_spin_us: float | None = None):
        """``wake_spin_us``: how long the node spins for more messages after a wake-up before it
        sleeps (see :mod:`emos.transport.waker`); default ``$EMOS_WAKE_SPIN_US`` or 100 us.
        Threaded mode passes 0: a spinning thread would hold the interpreter lock."""
        self.component = component
        if wake_spin_us is None:
            wake_spin_us = getattr(component, "_wake_spin_us", None)  # the Monitor: 0, see supervisor/monitor.py
        self.wake_spin_us = wake_spin_setting() if wake_spin_us is None else wake_spin_us
        self.wake_defer_s = float(getattr(component, "_wake_defer_s", 0.0))  # the Monitor: see _on_wake
        self.name = component.component_name
        self.ctx = ctx or current()
        self.supervisor_socket = supervisor_socket if supervisor_socket is not None else os.environ.get(ENV_SUPERVISOR_SOCKET)
        self.state = L.LifecycleState.UNCONFIGURED
        self.log = logging.getLogger(f"emos.{self.name}")
        self.loop: asyncio.AbstractEventLoop | None = None
        self.exit_code = 0
        self._stop: asyncio.Event | None = None
        self._exit_task: asyncio.Future[None] | None = None  # a signal's graceful exit (see _on_signal)
        self._waker: Waker | None = None
        self._inputs: dict[str, _Input] = {}
        # Publish stamp of the message that triggered the running step (None outside one): the
        # input's latest stamp may be newer when the step works through a backlog.
        self.trigger_stamp_ns: int | None = None
        self._deferred: list[tuple[int, int, _Input, Any]] = []  # triggering messages for the next pass (see _take_inputs)
        # Triggering messages that arrived while the component was not active (still configuring
        # or activating, or deactivated): stepped once it is active, up to each topic's queue
        # size (the newest); what fell out is counted per topic and said once at activation.
        self._held: list[tuple[int, int, _Input, Any]] = []
        self._held_dropped: dict[str, int] = {}
        self._publishers: dict[str, tuple[TopicPublisher, threading.Lock]] = {}
        self.publish_faults = PublishFaults()
        self._status_pub: Publisher | None = None
        self._status_lock = threading.Lock()
        self._last_status_ns = 0
        self._status_revision = -1  # the health status revision last published (see _run_step)
        self._main_timer: _Timer | None = None
        self._heartbeat: _Timer | None = None  # started by _main: a node driven by hand has none
        self._timers: list[_Timer | SimTimer] = []
        self._servers: list[Any] = []  # ServiceServer, ActionServer, and their Zenoh bridges
        self._extra_servers: list[tuple[str, tuple[Any, ...]]] = []
        self._control: RpcServer | None = None
        self._supervisor: AsyncRpcClient | None = None
        self._step_kwargs = component._step_accepts_kwargs()
        self._sim_time: SimTimeDriver | None = None  # config.use_sim_time: steps and answers on /clock
        self._been_active = False  # answers /clock ticks only once it has been active (see _take_inputs)
        self._step_errors = RateLimitedLog(interval=5.0)
        self.steps = 0

    # ============================================================================ running
    def run(self, install_signal_handlers: bool = True) -> int:
        """Run until told to exit; returns the exit code. Blocks the calling thread."""
        import uvloop

        self.loop = uvloop.new_event_loop()
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self._main(install_signal_handlers))
        finally:
            self.loop.close()
        return self.exit_code

    async def _main(self, install_signal_handlers: bool) -> None:
        self._stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        if install_signal_handlers:
            for sig in (signal.SIGTERM, signal.SIGINT):
                loop.add_signal_handler(sig, self._on_signal, sig)
        self.open_local()
        assert self._waker is not None
        loop.add_reader(self._waker.fd, self._on_wake)
        self._control = RpcServer(control_socket(self.ctx, self.name), self._control_ops(), name=self.name, max_frame=CONTROL_FRAME)
        await self._control.start()
        self._heartbeat = _Timer(loop, 1.0 / self.component.config.heartbeat_rate, self._heartbeat_tick)
        self.publish_status()
        try:
            await self._hello()
            await self._stop.wait()
        finally:
            await self._teardown()

    def open_local(self) -> None:
        """What a node needs before its first transition and that involves no supervisor: its
        wake-up FIFO and its status topic. ``_main`` and the test harness (``emos.testing``,
        which drives the node by hand on its own clock) both start here."""
        self.component._node = self
        # A best-effort component (the Monitor, the web UI) is woken after the robot's own readers.
        self._waker = Waker(self.ctx, spin_us=self.wake_spin_us, background=bool(getattr(self.component, "_wake_background", False)))
        self._status_pub = Publisher(self.ctx, self.component.status_topic.name, ComponentStatus, publisher_id=self.name, depth=16)

    def close_local(self) -> None:
        """Undo ``open_local`` (after the node is finalized)."""
        if self._waker is not None:
            if self.loop is not None and not self.loop.is_closed():
                self.loop.remove_reader(self._waker.fd)
            self._waker.close()
            self._waker = None
        if self._status_pub is not None:
            self._status_pub.close()
            self._status_pub = None
        self.component._node = None

    async def _hello(self) -> None:
        """Tell the supervisor we are up; it then drives our lifecycle through the control socket."""
        if not self.supervisor_socket:
            return
        self._supervisor = AsyncRpcClient(self.supervisor_socket)
        await self._supervisor.call(C.SUPERVISOR_HELLO, component=self.name, pid=os.getpid(), timeout=10.0)

    def _on_signal(self, sig: int) -> None:
        self.log.info("[%s] %s received: shutting down", self.name, signal.Signals(sig).name)
        # Held so the task is not garbage-collected before it runs to the end.
        self._exit_task = asyncio.ensure_future(self._graceful_exit())

    async def _graceful_exit(self, code: int = 0) -> None:
        if self.state != L.LifecycleState.FINALIZED:
            await self.transition(L.Transition.SHUTDOWN)
        self.exit_code = code
        assert self._stop is not None
        self._stop.set()

    def request_exit(self, code: int = 0) -> None:
        """Thread-safe: finalize and leave the loop."""
        if self.loop is not None and not self.loop.is_closed():
            self.loop.call_soon_threadsafe(lambda: asyncio.ensure_future(self._graceful_exit(code)))

    async def _teardown(self) -> None:
        if self._heartbeat is not None:
            self._heartbeat.cancel()
        if self.state != L.LifecycleState.FINALIZED:
            await self.transition(L.Transition.SHUTDOWN)
        self.publish_status()
        if self._supervisor is not None:
            await self._supervisor.close()
        if self._control is not None:
            await self._control.close()
        self.close_local()

    # ============================================================================ lifecycle
    async def transition(self, transition: L.Transition | str) -> L.LifecycleState:
        transition = L.Transition(transition)
        if transition == L.Transition.SHUTDOWN and self.state == L.LifecycleState.FINALIZED:
            return self.state
        target = L.next_state(self.state, transition)
        hook = {
            L.Transition.CONFIGURE: self._on_configure,
            L.Transition.ACTIVATE: self._on_activate,
            L.Transition.DEACTIVATE: self._on_deactivate,
            L.Transition.CLEANUP: self._on_cleanup,
            L.Transition.SHUTDOWN: self._on_shutdown,
        }[transition]
        try:
            await hook()
        except Exception as exc:
            self.log.exception("[%s] %s failed: %s", self.name, transition.value, exc)
            self.component.health_status.set_fail_component(component_names=[self.name], message=f"{transition.value} failed: {exc}")
            await self._release_all()
            recovered = False
            try:
                recovered = bool(self.component.custom_on_error())
            except Exception:
                self.log.exception("[%s] custom_on_error raised", self.name)
            self.state = L.LifecycleState.UNCONFIGURED if recovered and transition != L.Transition.SHUTDOWN else L.LifecycleState.FINALIZED
            self.publish_status()
            raise L.InvalidTransition(f"component {self.name!r}: {transition.value} failed: {exc}") from exc
        self.state = target
        self._been_active = self._been_active or target == L.LifecycleState.ACTIVE
        self.log.debug("[%s] %s -> %s", self.name, transition.value, target.value)
        self.publish_status()
        if target == L.LifecycleState.ACTIVE:
            self._on_wake()  # now active: step what arrived while it was not (see _take_inputs)
        return target

    async def _on_configure(self) -> None:
        for topic in self.component.out_topics:
            pub = open_publisher(self.ctx, topic, publisher_id=self.name, depth=topic.qos_profile.queue_size)
            self._publishers[topic.name] = (pub, threading.Lock())
        for topic in self.component.in_topics:
            sub = open_subscriber(self.ctx, topic, waker=self._waker, queue_size=topic.qos_profile.queue_size, transient_local=topic.qos_profile.transient_local,
                                  node_name=self.name)
            self._inputs[topic.name] = _Input(topic, sub)
        if self._waker is not None and self._waker.spin_ns and any(getattr(inp.sub, "threaded_delivery", False) for inp in self._inputs.values()):
            # Zenoh's threads deliver these inputs, and need the interpreter lock to do it, which
            # a spinning node holds nearly all the time: a message arriving during the spin
            # waited for its end, and the spin could never see it anyway (the reason threaded
            # mode does not spin either). So such a node sleeps at once.
            self.log.debug("[%s] inputs over Zenoh: no spin after a wake-up", self.name)
            self._waker.spin_ns = 0
        if getattr(self.component.config, "use_sim_time", False):
            assert self._waker is not None
            self._sim_time = SimTimeDriver(self.ctx, self.name, self._waker, lambda: 1.0 / self.component.config.loop_rate)
        self.component.custom_on_configure()

    async def _on_activate(self) -> None:
        comp = self.component
        ready = comp.custom_on_activate()
        if ready is not None:
            # It can serve once this completes (BaseComponent.custom_on_activate): the loop keeps
            # serving the heartbeat and the control socket while the state stays INACTIVE.
            await asyncio.wrap_future(ready)
        run_type = comp.run_type
        assert self.loop is not None
        if run_type == ComponentRunType.TIMED and self._sim_time is None:
            self._main_timer = _Timer(self.loop, 1.0 / comp.config.loop_rate, self._run_step)
        elif run_type == ComponentRunType.SERVER:
            req, resp = comp.main_srv_type  # type: ignore[misc]
            await self._start_server(ServiceServer(self.ctx, comp.main_srv_name, req, resp, self._serve_main, owner=self.name))
        elif run_type == ComponentRunType.ACTION_SERVER:
            goal, fb, res = comp.main_action_type  # type: ignore[misc]
            await self._start_server(ActionServer(self.ctx, comp.main_action_name, goal, fb, res, comp._main_action_callback, owner=self.name))
        for kind, args in self._extra_servers:
            if kind == "service":
                name, req, resp, callback = args
                await self._start_server(ServiceServer(self.ctx, name, req, resp, callback, owner=self.name))
            else:
                name, goal, fb, res, callback = args
                await self._start_server(ActionServer(self.ctx, name, goal, fb, res, callback, owner=self.name))

    async def _start_server(self, server: ServiceServer | ActionServer) -> None:
        await server.start()
        self._servers.append(server)
        bridge = open_server_bridge(self.ctx, server)  # only when the run shares it over Zenoh
        if bridge is not None:
            self._servers.append(bridge)

    async def _on_deactivate(self) -> None:
        await self._stop_activity()
        self.component.custom_on_deactivate()

    async def _stop_activity(self) -> None:
        if self._main_timer is not None:
            self._main_timer.cancel()
            self._main_timer = None
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        for server in self._servers:
            closing = server.close()  # a server closes with await, its Zenoh bridge at once
            if closing is not None:
                await closing
        self._servers.clear()

    async def _on_cleanup(self) -> None:
        self._close_topics()
        self._extra_servers.clear()  # declared at configure (create_service): the next configure declares them again
        self.component.custom_on_cleanup()

    async def _on_shutdown(self) -> None:
        was = self.state
        await self._stop_activity()
        if was == L.LifecycleState.ACTIVE:
            self.component.custom_on_deactivate()
        self.component.custom_on_shutdown()
        self._close_topics()

    async def _release_all(self) -> None:
        await self._stop_activity()
        self._close_topics()
        self._extra_servers.clear()

    def _close_topics(self) -> None:
        for pub, _ in self._publishers.values():
            pub.close()
        self._publishers.clear()
        for inp in self._inputs.values():
            inp.sub.close()
        self._inputs.clear()
        if self._sim_time is not None:
            self._sim_time.close()
            self._sim_time = None

    # ============================================================================ steps and data
    def _run_step(self, msg: Any = _NO_INPUT, topic: Any = None) -> None:
        """One step: with the message that triggered it (``msg``, on ``topic``), or none (a timer)."""
        comp = self.component
        sim_time = self._sim_time
        cpu0 = time.thread_time() if sim_time is not None else 0.0
        try:
            if msg is not _NO_INPUT and self._step_kwargs:
                comp._execution_step(msg=msg, topic=topic)
            else:
                comp._execution_step()
        except Exception as exc:
            # Catch, don't crash: the process lives on, reports COMPONENT_FAILURE, and fallbacks
            # (or the supervisor, if it never recovers) decide what happens next.
            self._step_errors.exception(exc, f"[{self.name}] execution step", logger=self.log)
            comp.health_status.set_fail_component(component_names=[self.name], message=f"{type(exc).__name__}: {exc}")
        if sim_time is not None:  # what a simulator that charges compute time delays our outputs by
            sim_time.compute_s += time.thread_time() - cpu0
        self.steps += 1
        if comp._status_after_step and comp.health_status.revision != self._status_revision:
            # Only a change: an unchanged status is already on the stream, and the heartbeat
            # repeats it. Publishing it after every step woke the supervisor and the run's
            # Zenoh helper at every message: 8 B between two components took 2.6x as long on
            # rings and 1.5x over Zenoh (docs/benchmarks-history.md, "A status after every step").
            self.publish_status()

    def _serve_main(self, request: Any) -> Any:
        response = self.component._main_srv_callback(request)
        self.steps += 1
        self.publish_status()
        return response

    def _on_wake(self) -> None:
        if self.wake_defer_s > 0:
            # A best-effort reader (the Monitor) lets the components woken by the same message
            # take the cores first. A blocking sleep, not a loop timer: uvloop's timers have
            # millisecond steps, and whatever arrives meanwhile is read in this same wake-up.
            time.sleep(self.wake_defer_s)
        if self._waker is not None:
            self._waker.serve(self._take_inputs, self._inputs_have_news)
        else:
            self._take_inputs()

    def _inputs_have_news(self) -> bool:
        for inp in self._inputs.values():
            if inp.sub.has_news():
                return True
        return self._sim_time is not None and self._sim_time.has_news()

    def _take_inputs(self) -> None:
        now = time.time_ns()
        active = self.state == L.LifecycleState.ACTIVE
        comp = self.component
        triggers = comp._trigger if comp.run_type == ComponentRunType.EVENT else ()
        sim_clock = self._sim_time
        tick = sim_clock.take() if sim_clock is not None else None  # before the inputs: see emos.core.clock
        # Every input's latest message first: a step must see the other inputs that arrived in
        # the same wake-up. Then one step per triggering message, all trigger topics merged in
        # publish order: a component (the Monitor above all) that was descheduled and wakes to a
        # backlog on two topics must not read all of one before the other, or it would pair
        # one topic's newest message with the other's oldest, a state that never existed.
        backlog, self._deferred = (self._deferred if active else []), []
        if active and self._held:
            backlog, self._held = self._held + backlog, []
            self._report_held_drops()
        for inp in self._inputs.values():
            items = inp.sub.take_raw()
            if not items:
                continue
            stamp, raw, _ = items[-1]
            inp.raw, inp.stamp_ns, inp.received_ns, inp.decoded = raw, stamp, now, None
            if inp.cache is not None:
                self._fill_cache(inp, items)
            inp.sim_at = sim_clock.time_at(stamp) if sim_clock is not None else None
            if inp.topic in triggers:
                if active and len(items) == 1:  # the usual case: no generator to run
                    backlog.append((stamp, len(backlog), inp, raw))
                elif active:
                    backlog.extend((stamp_i, len(backlog), inp, raw_i) for stamp_i, raw_i, _ in items)
                else:
                    self._hold(inp, [(stamp_i, raw_i) for stamp_i, raw_i, _ in items])
        if len(triggers) > 1 and backlog:
            # A message stamped while the rings were being read may have an earlier-stamped
            # sibling on a ring read before it was written: it waits for the next pass (at once).
            took = time.time_ns()
            self._deferred = [item for item in backlog if now <= item[0] <= took]
            if self._deferred:
                backlog = [item for item in backlog if not now <= item[0] <= took]
                assert self.loop is not None
                self.loop.call_soon(self._take_inputs)
        if len(backlog) > 1:
            backlog.sort(key=_STAMP_THEN_ORDER)  # by stamp; within a stamp, as read
        for stamp_i, _, inp, raw_i in backlog:
            msg = inp.decode(raw_i)
            inp.decoded = msg if raw_i is inp.raw else inp.decoded
            self.trigger_stamp_ns = stamp_i
            try:
                self._run_step(msg=msg, topic=inp.topic)
            finally:
                self.trigger_stamp_ns = None
        if tick is not None and self._sim_time is not None:  # after the inputs that came with the tick
            timed = active and self.component.run_type == ComponentRunType.TIMED
            # A node that has never been active does not answer: a lockstep simulator then waits
            # for it (republishing the tick) instead of running on while its inputs are dropped,
            # so whether a consumer sees the first scans does not depend on how fast it started.
            self._sim_time.handle(tick, self._run_step if timed else None, answer=self._been_active)

    def cache_input(self, topic: Topic | str, size: int) -> None:
        """Keep the newest ``size`` messages of an input, decoded, not only the latest (ROS's
        ``message_filters.Cache``): for a component that pairs a message with another input as
        it was at that message's stamp (a scan with the odometry when it was taken), which the
        latest alone cannot give once the component runs behind."""
        if not (isinstance(size, int) and size >= 1):
            name = topic.name if isinstance(topic, Topic) else topic
            raise ValueError(f"component {self.name!r}: cache_input({name!r}) size must be an int >= 1, got {size!r}")
        inp = self._input(topic)
        inp.cache = deque(inp.cache or (), maxlen=size)

    def cached(self, topic: Topic | str) -> list[Any]:
        """The messages kept by :meth:`cache_input`, oldest first (empty: none yet, or no cache)."""
        cache = self._input(topic).cache
        return list(cache) if cache is not None else []

    def _fill_cache(self, inp: _Input, items: list[tuple[int, Any, str]]) -> None:
        assert inp.cache is not None
        msg = None
        for _, raw, _ in items:
            try:
                msg = inp.decode(raw)
            except Exception as exc:  # noqa: BLE001 - one bad message must not stop the node's inputs
                msg = None
                self._step_errors.warning(("cache", inp.topic.name), "[%s] a message on %s did not decode: %s",
                                          self.name, inp.topic.name, exc, logger=self.log)
                continue
            inp.cache.append(msg)
        inp.decoded = msg  # the latest, decoded once (None: it did not decode, and latest() says why)

    def _hold(self, inp: _Input, items: list[tuple[int, Any]]) -> None:
        """Keep triggering messages that arrived while not active, the newest ``queue_size`` of
        each topic (as its ring would), for the first pass once active."""
        self._held.extend((stamp, len(self._held), inp, raw) for stamp, raw in items)
        keep = max(1, int(inp.topic.qos_profile.queue_size))
        mine = [item for item in self._held if item[2] is inp]
        if len(mine) > keep:
            drop = {id(item) for item in mine[:-keep]}
            self._held = [item for item in self._held if id(item) not in drop]
            self._held_dropped[inp.topic.name] = self._held_dropped.get(inp.topic.name, 0) + len(drop)

    def _report_held_drops(self) -> None:
        for topic, count in self._held_dropped.items():
            self.log.warning("[%s] %d message(s) on %s arrived while the component was not active and were not stepped "
                             "(beyond the topic's queue_size, the newest are kept for when it is active)", self.name, count, topic)
        self._held_dropped.clear()

    def _input(self, topic: Topic | str) -> _Input:
        name = topic.name if isinstance(topic, Topic) else normalize_topic_name(topic)
        try:
            return self._inputs[name]
        except KeyError:
            raise KeyError(f"component {self.name!r} has no input {name!r}; inputs: {sorted(self._inputs)}") from None

    def latest(self, topic: Topic | str) -> Any | None:
        inp = self._input(topic)
        if inp.raw is None:
            # Nothing seen through wake-ups yet (e.g. a transient-local message from before we
            # configured): look once.
            item = inp.sub.latest_raw()
            if item is None:
                return None
            inp.stamp_ns, inp.raw, _ = item
            inp.received_ns = time.time_ns()
            inp.sim_at = self._sim_time.time_at(inp.stamp_ns) if self._sim_time is not None else None
        if inp.decoded is None:
            inp.decoded = inp.decode(inp.raw)
        return inp.decoded

    def age(self, topic: Topic | str) -> float | None:
        """Seconds since the last message on ``topic`` (None: none yet). A node on simulated time
        counts simulated seconds: under lockstep a loaded machine slows the wall clock, not the
        robot's, and a command one control period old must not look stale (emos.core.clock)."""
        inp = self._input(topic)
        return None if inp.raw is None else self._age_s(inp)

    def _age_s(self, inp: _Input) -> float:
        if inp.sim_at is not None and self._sim_time is not None and self._sim_time.time is not None:
            age = self._sim_time.time - inp.sim_at
            if age >= 0.0:
                return age
            # Simulated time went back (the simulator restarted): fall back to the wall clock.
        return (time.time_ns() - inp.stamp_ns) / 1e9

    def publisher_pids(self, topic: Topic | str) -> list[int]:
        """Process ids of the publishers seen on ``topic`` (0 where a ring records none)."""
        return self._input(topic).sub.writer_pids()

    def publishers_alive(self, topic: Topic | str) -> bool | None:
        """Whether a process publishing on ``topic`` is alive: None if no publisher was ever seen.

        Lets a consumer tell "the producer died" (stop now) from "it is slow" (wait for the
        data timeout), e.g. the DriveManager when the controller process is killed."""
        pids = self.publisher_pids(topic)
        if not pids:
            return None
        return any(pid <= 0 or process_alive(pid) for pid in pids)

    def stale_inputs(self) -> list[str]:
        stale = []
        for name, inp in self._inputs.items():
            if inp.raw is None or (inp.topic.data_timeout and self._age_s(inp) > inp.topic.data_timeout):
                stale.append(name)
        return stale

    def publish(self, topic: Topic | str, msg: Any) -> None:
        # A name exactly as declared needs no normalizing (a key is its own normal form): that
        # check costs more than the rest of this method, on every message.
        entry = None
        if type(topic) is str:
            name = topic
            entry = self._publishers.get(topic)
        if entry is None:
            name = topic.name if isinstance(topic, Topic) else normalize_topic_name(topic)
            entry = self._publishers.get(name)
            if entry is None:
                raise self._no_output(name)
        pub, lock = entry
        if self.publish_faults.active:  # empty unless a chaos run switched a sensor fault on
            msg = self.publish_faults.apply(name, msg)
            if msg is None:
                return
        with lock:  # rings are single-writer; action threads and the loop may both publish
            pub.publish(msg)

    @contextlib.contextmanager
    def loan(self, topic: Topic | str, msg_type: type, shape: tuple[int, ...], dtype: Any = None, field: str = "data",
             **fields: Any) -> Iterator[Any]:
        """A loaned message on output ``topic``: its ``field`` array (``shape``, ``dtype``) is the
        ring slot itself, filled in place and published when the ``with`` block ends (given up
        if it raises). On Zenoh and ROS 2 outputs it is an ordinary array, copied once."""
        from emos.transport.loans import loan_from

        name = topic if type(topic) is str and topic in self._publishers else (
            topic.name if isinstance(topic, Topic) else normalize_topic_name(topic))
        entry = self._publishers.get(name)
        if entry is None:
            raise self._no_output(name)
        pub, lock = entry
        with lock, loan_from(pub, msg_type, shape, "uint8" if dtype is None else dtype, field, **fields) as msg:
            yield msg  # the ring is single-writer: nothing else publishes on it until the block ends

    def _no_output(self, name: str) -> Exception:
        if self.state not in (L.LifecycleState.INACTIVE, L.LifecycleState.ACTIVE):
            return RuntimeError(f"component {self.name!r} cannot publish on {name!r} while {self.state.value}")
        return KeyError(f"component {self.name!r} has no output {name!r}; outputs: {sorted(self._publishers)}")

    def publish_status(self) -> None:
        if self._status_pub is None:
            return
        health = self.component.health_status
        revision = health.revision  # before the snapshot: a change made after it is published next
        if self._write_status(health.to_msg(self.state.value)):
            self._status_revision = revision

    def _write_status(self, msg: ComponentStatus) -> bool:
        """Publish on the status ring (one writer: the loop, actions and callbacks may all call)."""
        with self._status_lock:
            if self._status_pub is None or self._status_pub.ring is None:
                return False
            self._status_pub.publish(msg)
            self._last_status_ns = time.monotonic_ns()
            return True

    def publish_status_message(self, msg: Any) -> None:
        """A status the component built itself (``health_status_publisher.publish``), published
        now on its status topic; an empty lifecycle state or pid is filled in with the node's."""
        if not isinstance(msg, ComponentStatus):
            raise TypeError(f"component {self.name!r}: health_status_publisher publishes a ComponentStatus "
                            f"(e.g. self.health_status()), got {type(msg).__name__}")
        if self._status_pub is None:
            raise RuntimeError(f"component {self.name!r}: its status topic is not open yet (the node is starting)")
        if not msg.lifecycle_state:
            msg.lifecycle_state = self.state.value
        if not msg.pid:
            msg.pid = os.getpid()
        self._write_status(msg)

    def _heartbeat_tick(self) -> None:
        period_ns = 1e9 / self.component.config.heartbeat_rate
        if time.monotonic_ns() - self._last_status_ns >= 0.9 * period_ns:
            self.publish_status()

    # ============================================================================ timers and servers
    def create_timer(self, period: float, callback: Callable[[], Any]) -> _Timer | SimTimer:
        """A periodic callback; on simulated time (``SimTimer``) in a ``use_sim_time`` node."""
        if self.loop is None:
            raise RuntimeError(f"component {self.name!r}: timers can only be created while running")
        timer: _Timer | SimTimer
        if self._sim_time is not None:
            timer = SimTimer(self._sim_time, period, callback, self.name)
        else:
            timer = _Timer(self.loop, period, callback)
        self._timers.append(timer)
        return timer

    def pacer(self, period: float) -> Pacer:
        """Paces an action loop that runs in a thread of its own at ``period`` seconds of this
        node's clock; in a ``use_sim_time`` node it steps inside the ticks, so a lockstep
        simulator waits for it (``emos.core.clock.Pacer``). Close it when the loop ends."""
        return Pacer(period, driver=self._sim_time)

    def hold_ticks_for(self, worker: Any) -> None:
        """In a ``use_sim_time`` node, answer each tick only once ``worker`` (a ``StepWorker``
        of this component) has done the steps of that tick (``SimTimeDriver.hold_ticks_for``);
        on the wall clock, nothing to do."""
        if self._sim_time is not None:
            self._sim_time.hold_ticks_for(worker)

    def release_ticks_from(self, worker: Any) -> None:
        if self._sim_time is not None:
            self._sim_time.release_ticks_from(worker)

    def add_service(self, name: str, request_type: Any, response_type: Any, callback: Any) -> None:
        self._extra_servers.append(("service", (name, request_type, response_type, callback)))

    def add_action_server(self, name: str, goal_type: Any, feedback_type: Any, result_type: Any, callback: Any) -> None:
        self._extra_servers.append(("action", (name, goal_type, feedback_type, result_type, callback)))

    def interfaces(self) -> list[tuple[str, str, tuple[Any, ...]]]:
        """``(kind, name, types)`` of the services and actions the component serves while it is
        active: its main one (Server / ActionServer run types) and those it created."""
        comp = self.component
        out: list[tuple[str, str, tuple[Any, ...]]] = []
        if comp.run_type == ComponentRunType.SERVER and comp.main_srv_type is not None:
            out.append(("service", comp.main_srv_name, tuple(comp.main_srv_type)))
        elif comp.run_type == ComponentRunType.ACTION_SERVER and comp.main_action_type is not None:
            out.append(("action", comp.main_action_name, tuple(comp.main_action_type)))
        for kind, args in self._extra_servers:
            out.append((kind, args[0], tuple(args[1:-1])))  # name, types..., callback
        out.extend(self.component.served_interfaces())
        return list({name: (kind, name, types) for kind, name, types in out}.values())  # one per name (socket)

    def on_config_changed(self) -> None:
        """Re-arm the main timer and heartbeat after a rate parameter changed."""
        if self._main_timer is not None and self.loop is not None:
            self._main_timer.period = 1.0 / self.component.config.loop_rate
        if self._heartbeat is not None:
            self._heartbeat.period = 1.0 / self.component.config.heartbeat_rate

    # ============================================================================ control socket
    def _control_ops(self) -> dict[str, Callable[..., Any]]:
        async def get_state(req: dict[str, Any], stream: Any) -> dict[str, Any]:
            h = self.component.health_status
            return {"state": self.state.value, "health": h.level.name, "pid": os.getpid(), "steps": self.steps, "run_type": self.component.run_type.value}

        async def transition(req: dict[str, Any], stream: Any) -> str:
            return (await self.transition(req["transition"])).value

        async def exit_(req: dict[str, Any], stream: Any) -> bool:
            asyncio.get_running_loop().call_soon(lambda: asyncio.ensure_future(self._graceful_exit(int(req.get("code", 0)))))
            return True

        async def info(req: dict[str, Any], stream: Any) -> dict[str, Any]:
            return {
                "component": self.name, "type": type(self.component).__name__, "state": self.state.value,
                "inputs": {t.name: t.type_name for t in self.component.in_topics},
                "outputs": {t.name: t.type_name for t in self.component.out_topics},
                "config": self.component.config.asdict(),
                # What `emos service list/call` and `emos action list/send_goal` find and type-check.
                **describe_interfaces(self.interfaces(), {s.name for s in self._servers if isinstance(s, (ServiceServer, ActionServer))}
                                      | {name for _kind, name, _types in self.component.served_interfaces()}),
            }

        # Calling a method (execute_method), parameters, files, topics, steps: emos.core.reconfig.
        return {C.GET_STATE: get_state, C.TRANSITION: transition, C.EXIT: exit_, C.INFO: info,
                **reconfig_ops(self), **fault_ops(self)}


class _Timer:
    """A drift-free periodic callback on an event loop; missed ticks are skipped, not queued."""

    def __init__(self, loop: asyncio.AbstractEventLoop, period: float, callback: Callable[[], Any]):
        if period <= 0:
            raise ValueError(f"timer period must be > 0 s, got {period}")
        self.loop, self.period, self.callback = loop, period, callback
        self._next = loop.time() + period
        self._handle: asyncio.TimerHandle | None = loop.call_at(self._next, self._tick)

    def _tick(self) -> None:
        if self._handle is None:
            return
        try:
            self.callback()
        finally:
            if self._handle is not None:
                now = self.loop.time()
                self._next += self.period
                if self._next < now:  # overran: skip to the next slot in the future
                    self._next = now + self.period - ((now - self._next) % self.period)
                self._handle = self.loop.call_at(self._next, self._tick)

    def cancel(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
