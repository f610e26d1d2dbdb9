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
from pathlib import Path
from typing import Any, cast

from emos.config.qos import QoSConfig
from emos.interop.ros2 import env
from emos.interop.ros2 import qos as Q
from emos.interop.ros2.options import STATE_FILE
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
# Fast DDS transports (Ros2Bridge's ``fastdds``, see _choose_transports): "udp" (the default), UDP
# only: a SIGKILLed bridge leaves no file, at the cost of UDP's copies, and of losses in the other
# node's socket buffer that the bridge cannot size (slower than shared memory for large messages,
# docs/ros2.md); "shm", shared memory between local processes (as ROS 2 nodes on this host use)
# and UDP. Fast DDS leaves /dev/shm/fastrtps_*
# behind when a process is SIGKILLed; with "shm" the bridge removes the segments of dead
# participants when it starts (fastdds_shm.py), but not yet the port segments that live peers
# still sending to the dead participant re-create (seen in tests/ros2/test_bridge.py's SIGKILL
# test), which is why "udp" stays the default.
FASTDDS_TRANSPORTS = ("udp", "shm")
ENV_FASTDDS_TRANSPORTS = "FASTDDS_BUILTIN_TRANSPORTS"
ENV_FASTDDS_PROFILES = "FASTRTPS_DEFAULT_PROFILES_FILE"  # Fast DDS 2 (Jazzy and older)
ENV_FASTDDS3_PROFILES = "FASTDDS_DEFAULT_PROFILES_FILE"  # Fast DDS 3 (Kilted on): the old name is deprecated there

# Sizes the bridge's participant asks of its transports. Large messages travel as ~64 KB
# fragments, all written in one burst; a fragment that finds no room is lost, and Fast DDS repairs
# it only after its reader's heartbeat-response and its writer's NACK-response delays (5 ms each),
# so every lost fragment costs ~10 ms (measured per stage in docs/ros2.md: a 921,600 B half
# round trip at 12-16 ms where the bridge's own work is ~1 ms).
# * UDP: the kernel's default receive buffer (net.core.rmem_default, 208 KB here) holds about three
#   fragments; the bridge's sockets ask for 8 MiB, which the kernel caps at net.core.rmem_max.
#   Only the receive side: with a large send buffer too, tests/ros2/test_bridge.py's 44 topics
#   at once failed to come back within a minute in 4 runs of 4 at load 50 (that test is
#   load-sensitive: HEAD's bridge passed 2 of 3, the receive buffer alone 1 of 2). A ROS 2
#   node's own receive buffer is its own: what the bridge sends it over UDP can still be lost
#   there (docs/ros2.md, Measured), which shared memory avoids.
# * Shared memory: Fast DDS's default segment is 512 KB, smaller than one 921,600 B image, so a
#   writer reuses the buffers of fragments its reader has not read yet; the bridge's segment
#   (its writers' memory) holds several large messages.
# * A burst whose last fragments and trailing heartbeat are both lost (the other node's small
#   socket buffer, under load) is noticed only at the writer's next periodic heartbeat: 3 s by
#   Fast DDS's default (measured: 921,600 B half round trips of 3 s); the bridge's writers send
#   one every 50 ms while a reader has not acknowledged everything (none otherwise).
# * A lost fragment costs its reader's heartbeat-response delay (when it asks for the fragment
#   again) plus its writer's NACK-response delay (when it re-sends it): Fast DDS's defaults are
#   5 ms each, the 9-10 ms half round trips of 921,600 B seen with ``shm`` (fragments are lost
#   where a buffer is smaller than a burst, e.g. a ROS 2 node's default 512 KB segment, which
#   cannot hold one image, when the bridge is slow to read it). The bridge answers at once on its side of each leg: as a reader it asks as soon
#   as a heartbeat shows a gap, as a writer it re-sends as soon as it is asked; a repair then
#   waits only on the other node's delay (~5 ms; measured: p99 of 80 921,600 B round trips
#   11-13 ms -> 6.2-6.5 ms). (The delays let a writer with many readers merge their requests;
#   a bridged topic has a few.)
HEARTBEAT_PERIOD_NS = 50_000_000
HEARTBEAT_RESPONSE_DELAY_NS = 0
NACK_RESPONSE_DELAY_NS = 0
UDP_SOCKET_BUFFER_BYTES = 8 * 1024 * 1024
SHM_SEGMENT_BYTES = 32 * 1024 * 1024
_MIN_SOCKET_BUFFER = 65_536  # Fast DDS's UDP transport needs a buffer of one whole datagram


def _socket_buffer(kind: str) -> int | None:
    """The socket buffer to ask for (``kind``: ``rmem``, receiving): ours, capped at what the
    kernel lets an unprivileged process set; None (Fast DDS's default) if that is too small."""
    try:
        most = int(Path(f"/proc/sys/net/core/{kind}_max").read_text())
    except (OSError, ValueError):
        most = UDP_SOCKET_BUFFER_BYTES
    size = min(UDP_SOCKET_BUFFER_BYTES, most)
    return size if size >= _MIN_SOCKET_BUFFER else None


def fastdds_profile(shm: bool, loopback_only: bool) -> str:
    """The bridge's Fast DDS XML profile: UDPv4 with a large receive buffer (on 127.0.0.1 only when
    ``loopback_only``), and with ``shm`` Fast DDS's shared-memory transport first, with a large
    segment (see ``SHM_SEGMENT_BYTES``); and its writers' and readers' reliability timing
    (``HEARTBEAT_PERIOD_NS``, ``NACK_RESPONSE_DELAY_NS``, ``HEARTBEAT_RESPONSE_DELAY_NS``). QoS
    policies come from ROS 2 as usual."""
    receive = _socket_buffer("rmem")
    buffers = f"\n      <receiveBufferSize>{receive}</receiveBufferSize>" if receive else ""
    where = "\n      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>" if loopback_only else ""
    shm_descriptor = f"""
    <transport_descriptor>
      <transport_id>emos_shm</transport_id>
      <type>SHM</type>
      <segment_size>{SHM_SEGMENT_BYTES}</segment_size>
    </transport_descriptor>""" if shm else ""
    ids = ("<transport_id>emos_shm</transport_id>" if shm else "") + "<transport_id>emos_udp</transport_id>"
    what = ("shared memory between local processes, " if shm else "no shared memory, ") + \
        ("UDP on 127.0.0.1 only" if loopback_only else "UDP") + ", large receive buffers"
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<!-- Written by the EMOS ROS 2 bridge: {what}. -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>{shm_descriptor}
    <transport_descriptor>
      <transport_id>emos_udp</transport_id>
      <type>UDPv4</type>{buffers}{where}
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="emos_bridge" is_default_profile="true">
    <rtps>
      <userTransports>{ids}</userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
  <data_writer profile_name="emos_bridge_writer" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>{HEARTBEAT_PERIOD_NS}</nanosec></heartbeatPeriod>
      <nackResponseDelay><sec>0</sec><nanosec>{NACK_RESPONSE_DELAY_NS}</nanosec></nackResponseDelay>
    </times>
  </data_writer>
  <data_reader profile_name="emos_bridge_reader" is_default_profile="true">
    <times>
      <heartbeatResponseDelay><sec>0</sec><nanosec>{HEARTBEAT_RESPONSE_DELAY_NS}</nanosec></heartbeatResponseDelay>
    </times>
  </data_reader>
</profiles>
"""


# The loopback-UDP profile, also given to the tests' and the benchmark's rclpy peers that must
# talk like the bridge.
_UDP_LOOPBACK_PROFILE = fastdds_profile(shm=False, loopback_only=True)


def _users_profile() -> str | None:
    return os.environ.get(ENV_FASTDDS_PROFILES) or os.environ.get(ENV_FASTDDS3_PROFILES)


def _choose_transports(ctx: RunContext, fastdds: str) -> str:
    """Set up this process's Fast DDS transports for ``fastdds`` (``FASTDDS_TRANSPORTS``);
    returns what was chosen, for the log.

    A user's own Fast DDS profile file (or ``FASTDDS_BUILTIN_TRANSPORTS``) is used as it is.
    Otherwise the bridge gives Fast DDS its own profile (:func:`fastdds_profile`): ``"udp"``,
    UDP only; ``"shm"``, shared memory and UDP, as ROS 2 nodes on this host use. When discovery
    is limited to this host (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` or the older
    ``ROS_LOCALHOST_ONLY=1``), the profile's UDP is on 127.0.0.1 only (the same reach) and the
    variables are taken out of this process's environment: with them rmw_fastrtps installs its
    own transports over the profile's."""
    if fastdds not in FASTDDS_TRANSPORTS:
        raise ValueError(f"ROS 2 bridge: fastdds must be one of {FASTDDS_TRANSPORTS}, got {fastdds!r}")
    users = _users_profile()
    if users:
        return f"Fast DDS profile {users} (the user's)"
    localhost = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST" or os.environ.get("ROS_LOCALHOST_ONLY") == "1"
    if os.environ.get(ENV_FASTDDS_TRANSPORTS) and not localhost:
        return f"Fast DDS transports {os.environ[ENV_FASTDDS_TRANSPORTS]} (the user's)"
    if fastdds == "shm":
        from emos.interop.ros2.fastdds_shm import remove_leftovers

        removed = remove_leftovers()
        if removed:
            log.info("ROS 2: removed %d Fast DDS shared-memory file(s) no live process used: %s", len(removed), ", ".join(sorted(removed)))
    path = ctx.run_dir / f"ros2_fastdds_{fastdds}{'_loopback' if localhost else ''}.xml"
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(fastdds_profile(shm=fastdds == "shm", loopback_only=localhost))
    os.replace(tmp, path)
    from emos.interop.ros2.env import find

    install = find()
    fastdds2 = install is None or install.distro in ("humble", "iron", "jazzy")
    os.environ[ENV_FASTDDS_PROFILES if fastdds2 else ENV_FASTDDS3_PROFILES] = str(path)
    os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    reach = "UDP on 127.0.0.1 only (discovery range LOCALHOST)" if localhost else "UDP"
    memory = f"shared memory ({SHM_SEGMENT_BYTES >> 20} MiB segment) between local processes and " if fastdds == "shm" else ""
    return f"Fast DDS {memory}{reach}, receive buffers {_socket_buffer('rmem')} B (profile {path})"


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


_READER_WAIT_S = 0.5  # the reader's wait when nothing comes: it only bounds how late it sees _stop


def _run_to_end(coroutine: Any) -> None:
    """Run an rclpy event handler's ``execute`` coroutine, which awaits nothing (its callback
    is a plain function), to its end in this thread."""
    try:
        coroutine.send(None)
    except StopIteration:
        return
    coroutine.close()  # it awaited something: not ours to drive
    log.warning("ROS 2 bridge: a QoS event handler waited for something; its event was dropped")


class _Reader:
    """Waits on a set of raw rclpy subscriptions and their QoS event handlers, and takes their
    samples and events, in the calling thread.

    The subscriptions are created on the bridge's node in :attr:`group`, which rclpy's executor
    never runs: it leaves the subscriptions and their event handlers out of its wait set. Both
    must be waited on in one place: while the executor waited on the events and this reader on
    the data, each woke the other's wait (apparently rmw_fastrtps's one listener per subscription,
    for its data and its events, wakes one wait set at a time) (measured at 8 B: the executor thread
    at 21 % of a CPU, 1.5-1.8 ms of bridge CPU per round trip, p50 2-3 ms under load; with one
    wait set, 0.42 ms and 0.39 ms). rclpy has no public wait-set API: this uses the one
    ``rclpy.wait_for_message`` and the executor use (``WaitSet``, ``take_message``, the
    ``Waitable`` methods of an event handler), unchanged from Humble to Kilted."""

    def __init__(self, context: Any):
        from rclpy import guard_condition
        from rclpy.callback_groups import CallbackGroup
        from rclpy.impl.implementation_singleton import rclpy_implementation

        class _TakenByReader(CallbackGroup):
            def can_execute(self, entity: Any) -> bool:
                return False  # neither the subscriptions nor their event handlers: see the class doc

            def beginning_execution(self, entity: Any) -> bool:
                return False

            def ending_execution(self, entity: Any) -> None:
                pass

        self.context = context
        self.group = _TakenByReader()
        self._rclpy = rclpy_implementation
        make_guard: Any = guard_condition.GuardCondition  # rclpy's code is untyped
        self._wake: Any = make_guard(None, None, context=context)  # on no node: the executor ignores it
        self._wait_set: Any = None
        self._size = (-1, -1)
        self._subs: list[Any] | None = None  # the set the fields below were gathered for (_prepare)
        self._events: list[Any] = []
        self._held: list[Any] = []
        self._by_pointer: dict[int, int] = {}

    def wake(self) -> None:
        """End the current wait (the set of subscriptions changed, or the bridge stops)."""
        try:
            self._wake.trigger()
        except Exception:  # destroyed: closing
            pass

    def wait(self, subs: list[Any], timeout_s: float) -> list[int] | None:
        """Wait until one of ``subs`` has a sample or an event (or :meth:`wake`, or
        ``timeout_s``); handles the events, returns the indexes of the subscriptions that have a
        sample, or None if the wait timed out.

        Called once per sample the bridge moves: what does not change between calls (the
        entities, their handles, the wait set) is gathered when ``subs`` changes (pass the same
        list object while the set is the same), and the handles are marked in use by plain
        calls, not an ExitStack (measured: 14 -> 9 us of Python per wait)."""
        if subs is not self._subs:
            self._prepare(subs)
        wait_set, events, held, by_pointer = self._wait_set, self._events, self._held, self._by_pointer
        entered = 0
        try:  # rclpy's handles must not be destroyed while waited on
            for handle in held:
                handle.__enter__()
                entered += 1
            wait_set.clear_entities()
            for sub in subs:
                wait_set.add_subscription(sub.handle)
            for event in events:
                event.add_to_wait_set(wait_set)
            wait_set.add_guard_condition(self._wake.handle)
            wait_set.wait(int(timeout_s * 1e9))
            fired = [e for e in events if e.is_ready(wait_set)] if events else events
            ready = wait_set.get_ready_entities("subscription")
            woken = bool(ready or fired or wait_set.get_ready_entities("guard_condition"))
        finally:
            for handle in held[entered - 1::-1] if entered else ():
                handle.__exit__(None, None, None)
        for event in fired:
            _run_to_end(event.execute(event.take_data()))
        if not woken:
            return None
        return [by_pointer[p] for p in ready if p in by_pointer]

    def _prepare(self, subs: list[Any]) -> None:
        """The entities of a new set of subscriptions, and a wait set of their size."""
        events = [e for sub in subs for e in sub.event_handlers]
        if self._size != (len(subs), len(events)):
            self._wait_set = self._rclpy.WaitSet(len(subs), 1, 0, 0, 0, len(events), self.context.handle)
            self._size = (len(subs), len(events))
        self._events = events
        self._held = [*(sub.handle for sub in subs), *events, self._wake.handle, self.context.handle]
        self._by_pointer = {sub.handle.pointer: i for i, sub in enumerate(subs)}
        self._subs = subs

    @staticmethod
    def take_all(sub: Any) -> Any:
        """Every sample ``sub`` holds now, as CDR bytes."""
        with sub.handle:
            while True:
                got = sub.handle.take_message(sub.msg_type, True)
                if got is None:
                    return
                yield got[0]

    def close(self) -> None:
        self._wake.destroy()


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
        self.transport = _choose_transports(ctx, fastdds)
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
            self._reader = _Reader(self.context)
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
            ready = reader.wait(subs, _READER_WAIT_S)
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
