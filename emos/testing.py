"""Test one component without a process tree: feed its inputs, move its clock, read its outputs.

``ComponentHarness`` runs the component's real ``Node`` in the calling thread, on real topics (the
shared-memory rings of a private run), but on a clock the test moves by hand: the harness plays
the simulator, publishing ``/clock`` ticks that the node follows as it follows a Simulator's
(``use_sim_time``). Timed steps, ``create_timer`` timers, input ages and ``emos.core.clock.now()``
all run on that clock, so a behaviour that takes 10 s of robot time is observed in as many
steps as it needs and in no wall time at all, the same on an idle laptop and a loaded CI machine::

    from emos.testing import ComponentHarness

    with ComponentHarness(driver) as h:           # configured and activated, clock at 0 s
        h.feed("/scan", scan)                     # published now, at the harness's time
        h.advance(0.5)                            # 0.5 s in ticks of 1/loop_rate: steps run
        commands = h.outputs("/cmd_vel")          # every message published since the last call
        assert h.health.is_healthy

The harness records everything the component publishes, tick by tick, so no ring's depth limits
what a test sees: ``outputs`` reads on from where it last read, ``mark``/``since`` read a stretch
without disturbing that. A closed loop (a base that moves as it is commanded) is a function
passed to ``advance(..., each_tick=...)`` that reads the commands and feeds the world's answer;
``play`` feeds a recorded stream one message per tick; ``call`` calls one of the component's
services through its socket, as another process would.

The component runs with ``use_sim_time`` set, as under a simulator: a component that behaves
differently on simulated time (the LocalMapper leaves stale-scan checks to the simulator's
lockstep) shows that behaviour here. Nothing but the harness runs the node: there is no
supervisor (no restarts, no fallbacks) and no heartbeat; services and action servers start but
are served only while the harness runs the node's event loop (``call``, ``run_pending``). Use a
process test for what needs those.
"""
from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from emos.core import clock as clock_mod
from emos.core import lifecycle as L
from emos.core.component import BaseComponent
from emos.core.node import Node
from emos.core.services import ServiceClient, ServiceServer
from emos.io.topic import Topic, normalize_topic_name
from emos.msgs import codec
from emos.msgs.std import Clock, Time
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber

__all__ = ["ComponentHarness"]

HARNESS_ID = "harness"  # publisher id of everything the harness feeds


class ComponentHarness:
    """Drives ``component`` by hand on a manual clock (module docstring).

    ``start_time``: the clock's first reading, in seconds. ``tick``: the clock's step in
    ``advance`` (default: the component's ``1 / loop_rate``, so a Timed component steps once per
    tick). ``activate=False`` stops after configure (call ``activate()`` yourself).
    """

    def __init__(self, component: BaseComponent, *, start_time: float = 0.0, tick: float | None = None, activate: bool = True):
        if not isinstance(component, BaseComponent):
            raise TypeError(f"ComponentHarness drives a BaseComponent, got {type(component).__name__}")
        if not math.isfinite(start_time) or start_time < 0:
            raise ValueError(f"ComponentHarness start_time must be a finite time >= 0 s, got {start_time}")
        if tick is not None and not (math.isfinite(tick) and tick > 0):
            raise ValueError(f"ComponentHarness tick must be a finite period > 0 s, got {tick}")
        if component._node is not None:
            raise RuntimeError(f"component {component.component_name!r} is already running")
        self.component = component
        self._tick = tick
        self._now_ns = int(round(start_time * 1e9))  # integer: a thousand ticks add up exactly
        self._ctx = RunContext.create()
        self._loop = asyncio.new_event_loop()
        self._publishers: dict[str, Publisher] = {}
        self._outputs: dict[str, Subscriber] = {}
        # Everything the component published, per topic: (sequence number, clock s, message).
        self._record: dict[str, list[tuple[int, float, Any]]] = {}
        self._read_upto: dict[str, int] = {}  # per topic: how many of its record ``outputs`` returned
        self._seq = 0
        self._clock: Publisher | None = None
        self.node: Node | None = None
        try:
            # The harness is this component's simulator: its ticks are the only clock it reads.
            component.config.use_sim_time = True
            self._clock = Publisher(self._ctx, clock_mod.CLOCK_TOPIC, Clock, publisher_id=HARNESS_ID, depth=64)
            self.node = Node(component, self._ctx, supervisor_socket="", wake_spin_us=0)
            self.node.loop = self._loop
            self.node.open_local()
            for topic in component.out_topics:
                self._outputs[topic.name] = Subscriber(self._ctx, topic.name, topic.msg_type, queue_size=max(64, topic.qos_profile.queue_size))
                self._record[topic.name] = []
            self._transition(L.Transition.CONFIGURE)
            self._publish_tick()  # the node knows the time before anything it does on activation
            self._handle()
            if activate:
                self.activate()
        except BaseException:
            self.close()
            raise

    # ---------------------------------------------------------------------------- lifecycle
    def activate(self) -> None:
        self._transition(L.Transition.ACTIVATE)
        self._handle()

    def deactivate(self) -> None:
        self._transition(L.Transition.DEACTIVATE)

    @property
    def state(self) -> L.LifecycleState:
        assert self.node is not None
        return self.node.state

    def _transition(self, transition: L.Transition) -> None:
        assert self.node is not None
        self._loop.run_until_complete(self.node.transition(transition))

    def close(self) -> None:
        """Shut the component down and release every topic, FIFO and segment of the run."""
        node, self.node = self.node, None
        try:
            if node is not None:
                try:
                    if node.state != L.LifecycleState.FINALIZED:
                        self._loop.run_until_complete(node.transition(L.Transition.SHUTDOWN))
                finally:
                    node.close_local()
        finally:
            for pub in self._publishers.values():
                pub.close()
            for sub in self._outputs.values():
                sub.close()
            self._publishers.clear()
            self._outputs.clear()
            if self._clock is not None:
                self._clock.close()
                self._clock = None
            self._loop.close()
            clock_mod.release_driven_time()
            self._ctx.remove_everything()

    def __enter__(self) -> ComponentHarness:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ---------------------------------------------------------------------------- time and data
    @property
    def time(self) -> float:
        """The clock's reading, in seconds."""
        return self._now_ns / 1e9

    @property
    def tick(self) -> float:
        return self._tick if self._tick is not None else 1.0 / self.component.config.loop_rate

    def feed(self, topic: Topic | str, msg: Any) -> None:
        """Publish ``msg`` on the input ``topic`` now; the node takes it at the next ``advance``
        or ``step`` (an Event component steps on it if it is a trigger)."""
        name = self._input_name(topic)
        pub = self._publishers.get(name)
        if pub is None:
            declared = next(t for t in self.component.in_topics if t.name == name)
            pub = self._publishers[name] = Publisher(self._ctx, name, declared.msg_type, publisher_id=HARNESS_ID)
        pub.publish(msg)

    def play(self, topic: Topic | str, messages: Iterable[Any], period: float | None = None) -> None:
        """Feed ``messages`` on ``topic`` one every ``period`` s of the clock (default: ``tick``),
        the first one now, advancing the clock after each: a recorded stream played back on
        robot time. The clock ends ``period`` after the last message."""
        period = self.tick if period is None else period
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"play takes a finite period > 0 s, got {period}")
        for msg in messages:
            self.feed(topic, msg)
            self.advance(period)

    def step(self) -> None:
        """Let the node take what was fed, without moving the clock."""
        self._handle()

    def advance(self, seconds: float, *, each_tick: Callable[[ComponentHarness], Any] | None = None) -> None:
        """Move the clock by ``seconds`` in ticks of ``tick`` (the last one shorter if need be);
        at each tick the node takes its inputs, runs the steps and timers that are due.

        ``each_tick(harness)`` runs before every tick, with the clock still at the previous one:
        the world around the component (a base that integrates the last command and feeds
        odometry and a scan, a controller that keeps sending) in lockstep with it."""
        if not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"advance takes a finite number of seconds >= 0, got {seconds}")
        end_ns = self._now_ns + int(round(seconds * 1e9))
        tick_ns = max(1, int(round(self.tick * 1e9)))
        while self._now_ns < end_ns:
            if each_tick is not None:
                each_tick(self)
            self._now_ns = min(end_ns, self._now_ns + tick_ns)
            self._publish_tick()
            self._handle()

    def outputs(self, topic: Topic | str) -> list[Any]:
        """Every message the component published on ``topic`` since the last call (oldest
        first; all of them: the harness records each tick's before a ring could drop any)."""
        name = self._output(topic)
        self._collect()
        record = self._record[name]
        start, self._read_upto[name] = self._read_upto.get(name, 0), len(record)
        return [msg for _, _, msg in record[start:]]

    def mark(self) -> int:
        """A point in the record of outputs: ``since(topic, mark)`` returns what came after it."""
        self._collect()
        return self._seq

    def since(self, topic: Topic | str, mark: int, *, times: bool = False) -> list[Any]:
        """Every message the component published on ``topic`` after ``mark`` (oldest first),
        as ``(clock s, message)`` pairs with ``times=True``; does not move ``outputs``."""
        name = self._output(topic)
        self._collect()
        return [(t, msg) if times else msg for seq, t, msg in self._record[name] if seq >= mark]

    def latest(self, topic: Topic | str) -> Any | None:
        """The newest message the component published on ``topic``, None if none."""
        name = self._output(topic)
        self._collect()
        record = self._record[name]
        return record[-1][2] if record else None

    def call(self, service: str, request: Any, timeout: float = 60.0) -> Any:
        """Call the component's service ``service`` with ``request`` through its socket, as
        another process would, and return the response. The node serves it meanwhile; the clock
        does not move. ``timeout`` (wall s) only bounds a hang."""
        server = self._server(service)
        client = ServiceClient(server.name, server.request_type, server.response_type, ctx=self._ctx, timeout=timeout)
        outcome: dict[str, Any] = {}

        def run() -> None:
            try:
                outcome["response"] = client.call(request)
            except BaseException as exc:  # noqa: BLE001 - raised again in the test's thread
                outcome["error"] = exc

        caller = threading.Thread(target=run, name=f"harness call {server.name}", daemon=True)
        caller.start()
        try:
            while caller.is_alive():
                self._loop.run_until_complete(asyncio.sleep(0.001))  # the node accepts and serves
        finally:
            caller.join()
            client.close()
        self._collect()
        if "error" in outcome:
            raise outcome["error"]
        return outcome["response"]

    @property
    def health(self) -> Any:
        return self.component.health_status

    def wait_for(self, condition: Callable[[], Any], timeout: float = 60.0, what: str = "the condition") -> Any:
        """For work the component does on threads of its own (a planner's worker): run the node's
        event loop, without moving the clock, until ``condition()`` returns something true, and
        return that. ``timeout`` (wall s) only bounds a hang: TimeoutError naming ``what``."""
        deadline = time.monotonic() + timeout
        while True:
            self._handle()
            value = condition()
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"component {self.component.component_name!r}: no {what} within {timeout:g} s of wall time "
                                   f"(clock at {self.time:.3f} s)")
            self._loop.run_until_complete(asyncio.sleep(0.002))

    def run_pending(self) -> None:
        """Run the node's event loop until it has nothing ready (serves pending service calls)."""
        self._loop.run_until_complete(asyncio.sleep(0))

    # ---------------------------------------------------------------------------- internals
    def _publish_tick(self) -> None:
        assert self._clock is not None
        self._clock.publish(Clock(clock=Time.from_sec(self.time)))

    def _handle(self) -> None:
        assert self.node is not None
        self.node._on_wake()  # what its event loop does when a publisher wakes it
        self.run_pending()  # what the node scheduled (a deferred input pass, a service reply)
        self._collect()

    def _collect(self) -> None:
        """Move what the component published into the record, stamped with the clock."""
        now = self.time
        for name, sub in self._outputs.items():
            for _, buf, _ in sub.take_raw():
                # A copy: a decoded array may still be a view of the ring, which wraps.
                self._record[name].append((self._seq, now, codec.decode(sub.msg_cls, buf, copy=True)))
                self._seq += 1

    def _input_name(self, topic: Topic | str) -> str:
        name = topic.name if isinstance(topic, Topic) else normalize_topic_name(topic)
        names = [t.name for t in self.component.in_topics]
        if name not in names:
            raise KeyError(f"component {self.component.component_name!r} has no input {name!r}; inputs: {sorted(names)}")
        return name

    def _output(self, topic: Topic | str) -> str:
        name = topic.name if isinstance(topic, Topic) else normalize_topic_name(topic)
        if name not in self._outputs:
            raise KeyError(f"component {self.component.component_name!r} has no output {name!r}; outputs: {sorted(self._outputs)}")
        return name

    def _server(self, service: str) -> ServiceServer:
        assert self.node is not None
        servers = [s for s in self.node._servers if isinstance(s, ServiceServer)]
        for server in servers:
            if server.name.strip("/") == service.strip("/"):
                return server
        raise KeyError(f"component {self.component.component_name!r} serves no service {service!r} while "
                       f"{self.node.state.value}; services: {sorted(s.name for s in servers)}")
