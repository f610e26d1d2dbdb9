"""A run's topics on the ROS 2 graph, and ROS 2 topics as ordinary EMOS inputs.

Why a bridge and not a ``ros2`` transport under every component
------------------------------------------------------------------
A transport would put rclpy, a DDS participant (threads, sockets, discovery traffic, Fast DDS's
shared-memory files) and ~130 ROS 2 libraries into *every* component process that touches a
bridged topic, and make their start-up, crash and restart behaviour depend on DDS's. One
supervised process that holds the only rclpy node instead:

* keeps components as they are: they read and write our rings; a topic is bridged or not by
  the run option, with no change to the recipe;
* has one participant on the graph (node ``emos_bridge``), one place for QoS matching,
  discovery and bad-input handling, one set of DDS resources to clean up;
* is restarted by the supervisor like any component when it dies; components do not notice
  beyond a gap in the bridged streams;
* costs one extra copy per message (ring -> CDR), measured in docs/ros2.md.

How
---
* EMOS -> ROS 2: every topic of the run that has an EMOS publisher, is wanted (``topics``: all,
  or names), and whose type is shared with ROS 2 (:mod:`emos.interop.ros2_cdr`) gets an rclpy
  publisher of the same name and ROS 2 type; messages go as CDR bytes (``publish(bytes)``, no
  rclpy message objects).
* ROS 2 -> EMOS: every wanted ROS 2 topic with a publisher other than this bridge, whose type has
  an EMOS class, gets a raw rclpy subscription (bytes) and an EMOS publisher (ring) of the same
  name; EMOS components subscribe to it as to any topic. These subscriptions are waited on and
  taken by the bridge's own reader thread (one wait set of just them), not by rclpy's executor,
  which rebuilds its whole wait set in Python about three times per sample and hands each one to
  a pool thread (measured: 3.2 executor passes and 3.2 pool hand-offs per 8 B sample).
* A topic goes one way only: the side that had a publisher first. ``/rosout`` and
  ``/parameter_events`` are bridged only when named.
* Bad input is dropped with one rate-limited line naming the topic and the types: a ROS 2 type
  EMOS has no class for, a topic whose type differs between the sides, bytes that do not decode,
  a ROS 2 interface package that is not installed.
* Incompatible QoS between the bridge and a ROS 2 node is reported once per topic and policy.
* Services of shared types go both ways (:mod:`emos.interop.ros2.services`), and so do actions
  (:mod:`emos.interop.ros2.actions`); an action's hidden ``<name>/_action/...`` topics are not
  bridged as topics.
"""
from __future__ import annotations

import fnmatch
import logging
import os
import threading
import time
from collections.abc import Iterable
from typing import Any, cast

from emos.config.qos import QoSConfig
from emos.interop.ros2 import env
from emos.interop.ros2 import qos as Q
from emos.interop.ros2.fastdds import choose_transports
from emos.interop.ros2.options import STATE_FILE
from emos.interop.ros2.reader import READER_WAIT_S, SampleReader
from emos.interop.ros2_cdr import DISTRIBUTIONS, CdrError, NotShared, codec_for
from emos.msgs import codec
from emos.msgs.registry import UnknownMessageType, resolve
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber, TopicTypeError, list_topics
from emos.transport.waker import Waker

log = logging.getLogger("emos.ros2")
_limited = RateLimitedLog(log, interval=10.0)

PUBLISHER_ID = "ros2_bridge"  # the bridge's rings: never bridged back out
ROS_INTERNAL = frozenset({"/rosout", "/parameter_events"})

class _Out:
    __slots__ = ("sub", "pub", "cls", "ros_type", "sent", "errors")

    def __init__(self, sub: Subscriber, pub: Any, cls: type, ros_type: str):
        self.sub, self.pub, self.cls, self.ros_type = sub, pub, cls, ros_type
        self.sent = self.errors = 0


class _In:
    __slots__ = ("sub", "pub", "cls", "ros_type", "received", "errors")

    def __init__(self, pub: Publisher, cls: type, ros_type: str):
        self.pub, self.cls, self.ros_type = pub, cls, ros_type
        self.sub: Any = None
        self.received = self.errors = 0


class Ros2Bridge:
    """Bridges the wanted topics of the run ``ctx`` to the ROS 2 graph of ``domain_id``.

    ``topics``: names or wildcards (``None`` or empty: all). ``qos``: per topic name, a QoSConfig,
    its fields or a profile name (:mod:`emos.interop.ros2.qos`). ``fastdds``: ``"udp"`` or
    ``"shm"`` (``FASTDDS_TRANSPORTS``). Runs three threads: the reader (ROS 2 -> EMOS topics),
    rclpy's executor (services, actions, QoS events) and the forwarder (EMOS -> ROS 2, and
    discovery every ``discover_every`` s). :attr:`failure` is set if one dies. :attr:`wakeups`
    counts the reader's and the forwarder's wake-ups (time-outs are not counted), and those that
    found nothing to move: a loop that spins shows there, per message
    (tests/ros2/test_bridge_cost.py).
    """

    def __init__(self, ctx: RunContext, topics: Iterable[str] | None = None, domain_id: int | None = None,
                 node_name: str = "emos_bridge", qos: dict[str, Any] | None = None, discover_every: float = 0.5,
                 fastdds: str = "udp"):
        self.install = env.ensure_loadable()
        self.transport = choose_transports(ctx, fastdds)
        import rclpy
        from rclpy.executors import MultiThreadedExecutor

        self.ctx = ctx
        self.patterns = [t if t.startswith("/") or "*" in t[:1] else "/" + t for t in (topics or [])]
        self.qos = {("/" + k.lstrip("/")): Q.as_qos(v, f"qos[{k!r}]") for k, v in (qos or {}).items()}
        self.discover_every = discover_every
        self.codec = codec_for(self.install.distro if self.install.distro in DISTRIBUTIONS else "jazzy")
        self.out: dict[str, _Out] = {}
        self.inn: dict[str, _In] = {}
        self._skipped: set[tuple[str, str]] = set()
        self._incompatible: set[tuple[str, str, str]] = set()
        self._lock = threading.Lock()  # out/inn tables: the forwarder adds, close() removes
        self._stop = threading.Event()
        self.failure: str | None = None
        self.wakeups = {"reader": 0, "reader_idle": 0, "forwarder": 0, "forwarder_idle": 0}
        self._in_version = 0  # bumped when the reader's subscriptions change
        self.context = rclpy.context.Context()
        from rclpy.signals import SignalHandlerOptions

        # The component's own SIGTERM handling stops it in order: rclpy must not take the signals over.
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node: Any = rclpy.create_node(node_name, context=self.context, start_parameter_services=False)
            self.node_name = self.node.get_name()
            self.node_namespace = self.node.get_namespace()
            # Three threads: the topics (the node's default, mutually exclusive group: one writer
            # per EMOS ring), calls to EMOS services, answers of ROS 2 servers (services.py).
            self.executor = MultiThreadedExecutor(num_threads=3, context=self.context)
            self.executor.add_node(self.node)
            self._reader = SampleReader(self.context)
            self.waker = Waker(ctx, background=True)
            from emos.interop.ros2.services import ServiceBridge

            self.services = ServiceBridge(ctx, self.node, self.wanted, self._skip_once)
            from emos.interop.ros2.actions import ActionBridge

            self.actions = ActionBridge(ctx, self.node, self.wanted, self._skip_once, self.services.loop)
        except BaseException:
            rclpy.shutdown(context=self.context)
            raise
        self.domain_id = self.context.get_domain_id()
        self._threads = [threading.Thread(target=self._guard, args=(self._read,), name="ros2-reader", daemon=True),
                         threading.Thread(target=self._guard, args=(self._spin,), name="ros2-executor", daemon=True),
                         threading.Thread(target=self._guard, args=(self._forward,), name="ros2-forwarder", daemon=True)]
        for t in self._threads:
            t.start()
        log.info("ROS 2 bridge: node /%s on domain %d, %s, %s; topics: %s", self.node_name, self.domain_id, self.install.describe(),
                 self.transport, ", ".join(self.patterns) or "all")

    # -- threads -------------------------------------------------------------------------------
    def _guard(self, body: Any) -> None:
        try:
            body()
        except Exception as exc:  # reported as the component's failure: the supervisor restarts it
            if not self._stop.is_set():
                self.failure = f"{threading.current_thread().name}: {type(exc).__name__}: {exc}"
                log.exception("ROS 2 bridge: %s", self.failure)

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.1)

    def _read(self) -> None:
        """ROS 2 -> EMOS: wait on the bridged subscriptions, take every sample, publish it."""
        reader, wakeups = self._reader, self.wakeups
        version = -1
        routes: list[tuple[str, _In]] = []
        subs: list[Any] = []  # the same list object until the set changes: the reader's cache
        while not self._stop.is_set() and self.context.ok():
            if version != self._in_version:
                with self._lock:
                    version = self._in_version
                    routes = [(t, r) for t, r in self.inn.items() if r.sub is not None]
                    subs = [r.sub for _t, r in routes]
            ready = reader.wait(subs, READER_WAIT_S)
            if ready is None:
                continue  # timed out: nothing came
            taken = 0
            for index in ready:
                topic, route = routes[index]
                for data in reader.take_all(route.sub):
                    self._receive(topic, route, data)
                    taken += 1
            wakeups["reader"] += 1
            if not taken:
                wakeups["reader_idle"] += 1

    def _forward(self) -> None:
        import select

        next_discovery = 0.0
        wakeups = self.wakeups
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_discovery:
                next_discovery = now + self.discover_every
                self.discover()
            readable, _, _ = select.select([self.waker.fd], [], [], 0.05)
            self.waker.drain()
            sent = self.forward_once()  # also after a time-out: a wake-up lost to a full FIFO is not a lost message
            if readable:
                wakeups["forwarder"] += 1
                if not sent:
                    wakeups["forwarder_idle"] += 1

    # -- which topics --------------------------------------------------------------------------
    def wanted(self, topic: str) -> bool:
        if not self.patterns:
            return topic not in ROS_INTERNAL
        return any(fnmatch.fnmatchcase(topic, p) for p in self.patterns)

    def _skip_once(self, topic: str, why: str, level: int = logging.WARNING) -> None:
        if (topic, why) not in self._skipped:
            self._skipped.add((topic, why))
            log.log(level, "ROS 2 bridge: %s not bridged: %s", topic, why)

    def discover(self) -> None:
        """Open the bridges of topics that appeared on either side since the last call."""
        def count() -> int:
            return len(self.out) + len(self.inn) + len(self.services.to_ros) + len(self.services.to_emos) + len(self.actions.summary())

        before = count()
        self._discover()
        if count() != before:
            self._write_state()

    def served_interfaces(self) -> list[tuple[str, str, tuple[Any, ...]]]:
        """``(kind, name, types)`` of the ROS 2 services and actions offered to EMOS, for the
        bridge component's ``info`` answer (``emos service list``). ``list()`` snapshots each
        table at once: discovery adds to them from the bridge's own threads."""
        services = [("service", name, (server.request_type, server.response_type))
                    for name, (server, _client) in list(self.services.to_emos.items())]
        actions = [("action", name, (route.server.goal_type, route.server.feedback_type, route.server.result_type))
                   for name, route in list(self.actions.to_emos.items())]
        return services + actions

    def _write_state(self) -> None:
        """``<run dir>/ros2_bridge.json``: the bridged topics, their direction and ROS 2 type, for
        ``emos topic list`` (written whole and renamed, so a reader never sees half of it)."""
        import json

        state = {"node": f"{self.node_namespace.rstrip('/')}/{self.node_name}", "domain_id": self.domain_id,
                 "topics": {t: {"direction": v["direction"], "type": v["type"]} for t, v in self.summary().items()},
                 "services": {**{n: "emos->ros2" for n in self.services.to_ros}, **{n: "ros2->emos" for n in self.services.to_emos}},
                 "actions": self.actions.summary()}
        path = self.ctx.run_dir / STATE_FILE
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        try:
            tmp.write_text(json.dumps(state, indent=1, sort_keys=True))
            os.replace(tmp, path)
        except OSError as exc:
            _limited.warning("state", "ROS 2 bridge: cannot write %s: %s", path, exc)

    def _discover(self) -> None:
        self.services.discover()
        self.actions.discover(set(self.services.to_ros) | set(self.services.to_emos))
        emos_topics = list_topics(self.ctx)
        # A topic a component carries on the ROS 2 graph itself (transport="ros2", direct.py) is
        # not bridged either way: its messages would reach the other side twice.
        from emos.interop.ros2.direct import direct_topics

        direct = direct_topics(self.ctx)
        for topic in direct:
            if self.wanted(topic):
                self._skip_once(topic, "a component carries it on the ROS 2 graph itself (transport='ros2')", logging.INFO)
        for topic, info in emos_topics.items():
            pubs = [p for p in info.get("publishers", []) if p != PUBLISHER_ID]
            if pubs and topic not in self.out and topic not in self.inn and topic not in direct and self.wanted(topic):
                self._open_out(topic, info["type"])
        for topic, types in self.node.get_topic_names_and_types():
            route = self.out.get(topic) or self.inn.get(topic)
            if route is not None:
                others = sorted(set(types) - {route.ros_type})
                if others:  # DDS keeps the two types apart: nothing flows between them
                    self._skip_once(topic, f"type differs between the sides: EMOS {route.ros_type}, ROS 2 {', '.join(others)}")
                continue
            if not self.wanted(topic) or "/_action/" in topic or topic in direct:  # an action's own topics: actions.py bridges the action
                continue
            publishers = [p for p in self.node.get_publishers_info_by_topic(topic)
                          if (p.node_name, p.node_namespace) != (self.node_name, self.node_namespace)]
            if publishers:
                self._open_in(topic, types, publishers, emos_topics.get(topic))

    def _open_out(self, topic: str, type_name: str) -> None:
        try:
            cls = resolve(type_name)
            ros_type = self.codec.ros_type(cls)
        except UnknownMessageType:
            self._skip_once(topic, f"EMOS type {type_name} is not known in this process")
            return
        except NotShared as exc:
            self._skip_once(topic, f"EMOS type {type_name} has no ROS 2 counterpart ({exc})", logging.INFO)
            return
        msg_cls = self._ros_class(topic, ros_type)
        if msg_cls is None:
            return
        qos = self.qos.get(topic) or Q.default_for(topic)
        from rclpy.event_handler import PublisherEventCallbacks

        events = PublisherEventCallbacks(incompatible_qos=lambda info: self._incompatible_qos(topic, "EMOS -> ROS 2", qos, info))
        pub = self.node.create_publisher(msg_cls, topic, Q.to_ros(qos), event_callbacks=events)
        try:
            sub = Subscriber(self.ctx, topic, cls, waker=self.waker, queue_size=max(qos.queue_size, 16), transient_local=qos.transient_local, loans=1)
        except BaseException:
            self.node.destroy_publisher(pub)
            raise
        with self._lock:
            self.out[topic] = _Out(sub, pub, cls, ros_type)
        log.info("ROS 2 bridge: %s (%s) EMOS -> ROS 2, %s", topic, ros_type, Q.describe(qos))

    def _open_in(self, topic: str, types: list[str], publishers: list[Any], emos_info: dict[str, Any] | None) -> None:
        if len(types) != 1:
            self._skip_once(topic, f"ROS 2 publishers disagree on its type ({', '.join(types)})")
            return
        ros_type = types[0]
        try:
            cls = self.codec.class_for(ros_type)
        except NotShared as exc:
            self._skip_once(topic, f"ROS 2 type {ros_type} has no EMOS counterpart ({exc})")
            return
        emos_type = (emos_info or {}).get("type")
        if emos_type not in (None, "?") and emos_type != ros_type:
            self._skip_once(topic, f"type differs between the sides: EMOS {emos_type}, ROS 2 {ros_type}")
            return
        msg_cls = self._ros_class(topic, ros_type)
        if msg_cls is None:
            return
        qos = self.qos.get(topic) or Q.matching_subscription([p.qos_profile for p in publishers])
        pub = Publisher(self.ctx, topic, cls, publisher_id=PUBLISHER_ID, depth=max(qos.queue_size, 10))
        route = _In(pub, cls, ros_type)
        from rclpy.event_handler import SubscriptionEventCallbacks

        events = SubscriptionEventCallbacks(incompatible_qos=lambda info: self._incompatible_qos(topic, "ROS 2 -> EMOS", qos, info))
        try:
            # The callback is never called: the reader thread takes the samples (_read).
            route.sub = self.node.create_subscription(msg_cls, topic, lambda data: self._receive(topic, route, cast(bytes, data)), Q.to_ros(qos),
                                                      raw=True, event_callbacks=events, callback_group=self._reader.group)
        except BaseException:
            pub.close()
            raise
        with self._lock:
            self.inn[topic] = route
            self._in_version += 1
        self._reader.wake()
        log.info("ROS 2 bridge: %s (%s) ROS 2 -> EMOS, %s", topic, ros_type, Q.describe(qos))

    def _ros_class(self, topic: str, ros_type: str) -> Any:
        try:
            return env.message_class(ros_type, self.install.distro)
        except ImportError as exc:
            self._skip_once(topic, str(exc))
            return None

    def _incompatible_qos(self, topic: str, direction: str, ours: QoSConfig, info: Any) -> None:
        policy = getattr(getattr(info, "last_policy_kind", None), "name", str(getattr(info, "last_policy_kind", "?")))
        key = (topic, direction, policy)
        if key not in self._incompatible:
            self._incompatible.add(key)
            log.warning("ROS 2 bridge: topic %s (%s): a ROS 2 node's QoS is incompatible with the bridge's %s on policy %s; "
                        "no messages flow between them", topic, direction, Q.describe(ours), policy)

    # -- moving messages -----------------------------------------------------------------------
    def forward_once(self) -> int:
        """EMOS -> ROS 2: publish what arrived on the bridged rings; returns how many."""
        sent = 0
        for topic, route in list(self.out.items()):
            try:
                got = route.sub.take_raw()
            except TopicTypeError as exc:
                route.errors += 1
                _limited.error(f"type:{topic}", "ROS 2 bridge: topic %s (%s): %s", topic, route.ros_type, exc)
                continue
            for _stamp, frame, _pub in got:
                try:
                    data = self.codec.serialize(codec.decode(route.cls, frame))
                except Exception as exc:  # one bad message must not stop the topic or the bridge
                    route.errors += 1
                    _limited.error(f"out:{topic}", "ROS 2 bridge: topic %s: an EMOS %s message not sent as %s: %s",
                                   topic, route.cls.__name__, route.ros_type, exc)
                    continue
                route.pub.publish(data)
                route.sent += 1
                sent += 1
        return sent

    def _receive(self, topic: str, route: _In, data: bytes) -> None:
        """ROS 2 -> EMOS (rclpy's executor thread): one raw CDR sample."""
        try:
            msg = self.codec.deserialize(route.cls, data)
        except CdrError as exc:
            route.errors += 1
            _limited.warning(f"in:{topic}", "ROS 2 bridge: topic %s: a malformed %s sample (%d bytes) dropped: %s",
                             topic, route.ros_type, len(data), exc)
            return
        try:
            route.pub.publish(msg)
        except Exception as exc:  # a value our codec refuses (e.g. too big for a ring)
            route.errors += 1
            _limited.warning(f"in-pub:{topic}", "ROS 2 bridge: topic %s: a %s sample not published to EMOS: %s", topic, route.ros_type, exc)
            return
        route.received += 1

    # -- state ---------------------------------------------------------------------------------
    def alive(self) -> bool:
        return self.failure is None and all(t.is_alive() for t in self._threads)

    def summary(self) -> dict[str, dict[str, Any]]:
        out = {t: {"direction": "emos->ros2", "type": r.ros_type, "messages": r.sent, "errors": r.errors} for t, r in self.out.items()}
        out.update({t: {"direction": "ros2->emos", "type": r.ros_type, "messages": r.received, "errors": r.errors}
                    for t, r in self.inn.items()})
        return out

    def close(self) -> None:
        import rclpy

        self._stop.set()
        self._reader.wake()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=5.0)
        with self._lock:
            outs, ins = list(self.out.values()), list(self.inn.values())
            self.out.clear()
            self.inn.clear()
        for o in outs:
            o.sub.close()
        for i in ins:
            i.pub.close()
        try:
            self.actions.close()
            self.services.close()
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
            self._reader.close()
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)
            self.waker.close()
