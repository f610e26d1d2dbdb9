"""Topics declared ``Topic(..., transport="ros2")``: on the ROS 2 graph from the component's own process.

The default way to ROS 2 is the bridge (:mod:`emos.interop.ros2.bridge`, docs/ros2.md: one
supervised process holds the only DDS participant). A topic that opts in with
``transport="ros2"`` skips it: its publisher and subscriber are rclpy's, in the component's
process, so a message makes no hop through the bridge's process (measured in docs/ros2.md: at
8 B the bridge's wake-ups and hops were most of EMOS <-> rclpy's latency). What it costs: rclpy,
a DDS participant and its threads in that process, and a start-up of about a second on the
first such topic.

* One rclpy context and node per process, made on the first ``ros2`` topic (:func:`participant`)
  and shut down when the last one closes (the component stops). The node is named after the
  component (the publisher id the node passes, else the process name); the domain is the run's
  (``emos run --ros-domain-id`` / ``use_ros2(domain_id=...)``), else ``$ROS_DOMAIN_ID``.
* ROS 2 is found and loaded as the bridge does it (:mod:`emos.interop.ros2.env`), names and QoS
  map as the bridge maps them (:mod:`emos.interop.ros2.qos`: the topic's own ``qos_profile``, or
  when it is left at its default, the bridge's default for the name: latched for ``/map``, ...),
  and messages travel as CDR bytes (:mod:`emos.interop.ros2_cdr`; a type with no ROS 2
  counterpart fails when the topic is opened, naming it).
* Fast DDS's transports are the bridge's (:mod:`emos.interop.ros2.fastdds`): loopback-safe UDP by default,
  or shared memory with ``$EMOS_ROS2_FASTDDS=shm``; with shared memory a participant removes, when
  it starts, the Fast DDS files of dead participants (:mod:`emos.interop.ros2.fastdds_shm`), so a
  component SIGKILLed and restarted cleans what it left.
* Subscriptions are raw and waited on by one reader thread per process on a wait set of just
  them (:class:`emos.interop.ros2.reader.SampleReader`, as the bridge's). It decodes each sample there (``decodes_on_arrival``,
  as Zenoh's subscriber), queues it and wakes the node; a sample that is not valid CDR of the
  topic's type is dropped with one rate-limited line naming the topic and the type.
* Each topic carried this way is recorded in ``<run dir>/ros2_direct/`` so that the run's bridge
  does not bridge it too (:func:`direct_topics`).
"""
from __future__ import annotations

import json
import logging
import os
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from emos.config.qos import QoSConfig
from emos.errors import TransportError
from emos.interop.ros2 import env
from emos.interop.ros2 import qos as Q
from emos.interop.ros2.fastdds import FASTDDS_TRANSPORTS, choose_transports
from emos.interop.ros2.reader import READER_WAIT_S, SampleReader
from emos.interop.ros2_cdr import DISTRIBUTIONS, CdrError, NotShared, Ros2Codec, codec_for
from emos.msgs.registry import canonical_name
from emos.ratelimit import RateLimitedLog
from emos.transport.arrivals import ArrivalQueue
from emos.transport.context import RunContext, decode_name, encode_name

log = logging.getLogger("emos.ros2.direct")
_limited = RateLimitedLog(log, interval=10.0)

ENV_FASTDDS = "EMOS_ROS2_FASTDDS"  # "udp" (default) or "shm": the Fast DDS transports of ros2 topics
DIRECT_DIR = "ros2_direct"  # in the run directory: one file per topic carried directly
_NODE_NAME_BAD = re.compile(r"[^A-Za-z0-9_]")


class Ros2TopicError(TransportError, RuntimeError):
    """A ``transport="ros2"`` topic that cannot be opened (its type has no ROS 2 counterpart, ...)."""


def node_name_for(name: str) -> str:
    """A valid ROS 2 node name from a component's name (``nav/planner-1`` -> ``nav_planner_1``)."""
    cleaned = _NODE_NAME_BAD.sub("_", name).strip("_") or "emos"
    return cleaned if not cleaned[0].isdigit() else f"emos_{cleaned}"


# ------------------------------------------------------------------------------- the run's record
def _record(ctx: RunContext, topic: str, ros_type: str, direction: str, node: str) -> None:
    """Note in the run directory that ``topic`` is carried directly (the bridge reads it). Kept for
    the run: a component that restarts declares the same topics again."""
    folder = ctx.run_dir / DIRECT_DIR
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        path = folder / f"{encode_name(topic)}.{direction}"
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"topic": topic, "type": ros_type, "direction": direction, "node": node}))
        os.replace(tmp, path)
    except OSError as exc:
        _limited.warning(f"record:{topic}", "ROS 2 topic %s: cannot record it in %s (the bridge may bridge it too): %s", topic, folder, exc)


def direct_topics(ctx: RunContext) -> frozenset[str]:
    """The topics of the run that components carry directly (``transport="ros2"``)."""
    return frozenset(direct_records(ctx))


def direct_records(ctx: RunContext) -> dict[str, dict[str, Any]]:
    """``{topic: {"type": ROS 2 type, "pub": [node, ...], "sub": [node, ...]}}`` of the topics
    components carry directly, from the run's record (read as untrusted: a file that is not a
    record of ours is skipped, and a damaged one only loses its type and node)."""
    folder = ctx.run_dir / DIRECT_DIR
    try:
        names = os.listdir(folder)
    except OSError:
        return {}
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        base, dot, direction = name.rpartition(".")
        if not dot or direction not in ("pub", "sub"):
            continue
        try:
            topic = decode_name(base)
        except ValueError:
            continue  # not ours: the folder is only read, never trusted beyond a name
        entry = out.setdefault(topic, {"type": "?", "pub": [], "sub": []})
        try:
            record = json.loads((folder / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(record, dict):
            if isinstance(record.get("type"), str):
                entry["type"] = record["type"]
            if isinstance(record.get("node"), str):
                entry[direction].append(record["node"])
    return out


# ------------------------------------------------------------------------------- the participant
class _Participant:
    """This process's rclpy context, node and reader thread, shared by its ``ros2`` topics."""

    def __init__(self, ctx: RunContext, name: str):
        from emos.interop.ros2.options import from_environment

        self.install = env.ensure_loadable()
        fastdds = os.environ.get(ENV_FASTDDS, "udp") or "udp"
        if fastdds not in FASTDDS_TRANSPORTS:
            raise ValueError(f"${ENV_FASTDDS} must be one of {', '.join(FASTDDS_TRANSPORTS)}, got {fastdds!r}")
        self.transport = choose_transports(ctx, fastdds)
        _enabled, _topics, domain = from_environment()
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        self.ctx = ctx
        self.codec: Ros2Codec = codec_for(self.install.distro if self.install.distro in DISTRIBUTIONS else "jazzy")
        self.context = rclpy.context.Context()
        # The component's own SIGTERM handling stops it in order: rclpy must not take the signals over.
        rclpy.init(context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node: Any = rclpy.create_node(node_name_for(name), context=self.context, start_parameter_services=False)
            self.reader = SampleReader(self.context)
        except BaseException:
            rclpy.shutdown(context=self.context)
            raise
        self.users = 0
        self._lock = threading.Lock()
        self._subs: list[Ros2Subscriber] = []
        self._version = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="ros2-direct-reader", daemon=True)
        self._thread.start()
        log.info("ROS 2: node /%s on domain %d in this process (topics with transport='ros2'), %s, %s", self.node.get_name(),
                 self.context.get_domain_id(), self.install.describe(), self.transport)

    def ros_class(self, topic: str, ros_type: str) -> Any:
        try:
            return env.message_class(ros_type, self.install.distro)
        except ImportError as exc:
            raise Ros2TopicError(f"ROS 2 topic {topic}: {exc}") from None

    def add(self, sub: Ros2Subscriber) -> None:
        with self._lock:
            self._subs.append(sub)
            self._version += 1
        self.reader.wake()

    def remove(self, sub: Ros2Subscriber) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
                self._version += 1
        self.reader.wake()

    def _read(self) -> None:
        """Wait on this process's subscriptions, take every sample, hand it to its subscriber."""
        version = -1
        subs: list[Ros2Subscriber] = []
        handles: list[Any] = []  # the same list object until the set changes: the reader's cache
        while not self._stop.is_set():
            if version != self._version:
                with self._lock:
                    version = self._version
                    subs = list(self._subs)
                    handles = [s.rclpy_sub for s in subs]
            try:
                ready = self.reader.wait(handles, READER_WAIT_S)
            except Exception as exc:  # noqa: BLE001 - a subscription destroyed under the wait: the set changed
                if self._stop.is_set():
                    return
                if version == self._version:
                    _limited.error("wait", "ROS 2 reader: waiting failed: %s", exc)
                    time.sleep(0.05)
                continue
            for index in ready or ():
                sub = subs[index]
                try:
                    for data in self.reader.take_all(sub.rclpy_sub):
                        sub.deliver(data)
                except Exception as exc:  # noqa: BLE001 - closed meanwhile, or rclpy refused: the others go on
                    if not sub.closed:
                        _limited.error(f"take:{sub.topic}", "ROS 2 topic %s: taking a sample failed: %s", sub.topic, exc)

    def close(self) -> None:
        import rclpy

        self._stop.set()
        self.reader.wake()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        try:
            self.node.destroy_node()
            self.reader.close()
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)
        log.info("ROS 2: node of this process closed")


_participant: tuple[int, _Participant] | None = None  # (pid, participant): a forked child makes its own
_participant_lock = threading.Lock()


def participant(ctx: RunContext, name: str) -> _Participant:
    """This process's participant, made on first use, with one more user (:func:`release`)."""
    global _participant
    with _participant_lock:
        if _participant is None or _participant[0] != os.getpid():
            _participant = (os.getpid(), _Participant(ctx, name))
        part = _participant[1]
        part.users += 1
        return part


def release(part: _Participant) -> None:
    """One user fewer; the last one shuts the participant down (the component stopped)."""
    global _participant
    with _participant_lock:
        part.users -= 1
        if part.users > 0 or _participant is None or _participant[1] is not part:
            return
        _participant = None
    part.close()


def _process_name() -> str:
    try:
        with open("/proc/self/comm") as f:
            return f.read().strip().removeprefix("emos:")
    except OSError:
        return f"emos_{os.getpid()}"


def _qos_of(topic: str, qos: QoSConfig | None) -> QoSConfig:
    """The topic's QoS, or the bridge's default for its name when the recipe left it at the default."""
    return qos if qos is not None and qos != QoSConfig() else Q.default_for(topic)


# ------------------------------------------------------------------------------- endpoints
def _endpoint(part: _Participant, topic: str, msg_cls: type, qos: QoSConfig | None) -> tuple[str, QoSConfig, Any]:
    """``(ROS 2 type name, QoS, rclpy class)`` of a topic opened in this process, or a
    :class:`Ros2TopicError` that names the topic and what is missing."""
    try:
        ros_type = part.codec.ros_type(msg_cls)
    except NotShared as exc:
        raise Ros2TopicError(f"ROS 2 topic {topic}: EMOS type {canonical_name(msg_cls)} has no ROS 2 counterpart ({exc})") from None
    return ros_type, _qos_of(topic, qos), part.ros_class(topic, ros_type)


class Ros2Publisher:
    """Publishes one topic's messages on the ROS 2 graph as CDR bytes, from this process."""

    def __init__(self, ctx: RunContext, topic: str, msg_cls: type, publisher_id: str | None = None, qos: QoSConfig | None = None):
        self.topic, self.msg_cls = topic, msg_cls
        self.type_name = canonical_name(msg_cls)
        self._part = participant(ctx, publisher_id or _process_name())
        try:
            self.codec = self._part.codec
            self.ros_type, self.qos, ros_cls = _endpoint(self._part, topic, msg_cls, qos)
            # Recorded before it appears on the graph: the bridge must never see it unrecorded.
            _record(ctx, topic, self.ros_type, "pub", self._part.node.get_name())
            self._pub: Any = self._part.node.create_publisher(ros_cls, topic, Q.to_ros(self.qos))
        except BaseException:
            release(self._part)
            raise
        self.sent = 0
        log.info("ROS 2 topic %s (%s) published from this process, %s", topic, self.ros_type, Q.describe(self.qos))

    def publish(self, msg: Any) -> int:
        if not isinstance(msg, self.msg_cls):
            from emos.transport.pubsub import TopicTypeError

            raise TopicTypeError(f"topic {self.topic!r} carries {self.type_name}, got {type(msg).__name__}")
        pub = self._pub
        if pub is None:
            raise RuntimeError(f"ROS 2 topic {self.topic!r}: the publisher is closed")
        pub.publish(self.codec.serialize(msg))
        self.sent += 1
        return self.sent - 1

    def close(self) -> None:
        pub, self._pub = self._pub, None
        if pub is None:
            return
        try:
            self._part.node.destroy_publisher(pub)
        except Exception as exc:  # noqa: BLE001 - the node may be gone already
            log.debug("ROS 2 topic %s: destroying the publisher: %s", self.topic, exc)
        release(self._part)


class Ros2Subscriber(ArrivalQueue):
    """Receives one topic from every ROS 2 publisher, in this process. The reading interface of
    :class:`emos.transport.pubsub.Subscriber` (``take_raw``, ``latest_raw``, ``has_news``, ...);
    payloads are the messages, decoded on the reader thread (``decodes_on_arrival``), which then
    calls ``notify`` (the node's waker) holding no lock. The queue and close protocol are
    :class:`emos.transport.arrivals.ArrivalQueue`'s, as Zenoh's subscriber."""

    decodes_on_arrival = True
    threaded_delivery = True  # the reader thread needs the interpreter lock to deliver: the node must not spin

    def __init__(self, ctx: RunContext, topic: str, msg_cls: type, notify: Callable[[], None] | None = None, queue_size: int = 10,
                 qos: QoSConfig | None = None, node_name: str | None = None):
        self.msg_cls = msg_cls
        self.type_name = canonical_name(msg_cls)
        ArrivalQueue.__init__(self, topic, queue_size, notify, _limited)
        self.rejected = 0  # samples that were not valid CDR of the topic's type
        self._part = participant(ctx, node_name or _process_name())
        try:
            self.codec = self._part.codec
            self.ros_type, self.qos, ros_cls = _endpoint(self._part, topic, msg_cls, qos)
            _record(ctx, topic, self.ros_type, "sub", self._part.node.get_name())  # before it is on the graph (see Ros2Publisher)
            from rclpy.event_handler import SubscriptionEventCallbacks

            events = SubscriptionEventCallbacks(incompatible_qos=self._incompatible_qos)
            # The callback is never called: the reader thread takes the samples.
            self.rclpy_sub: Any = self._part.node.create_subscription(ros_cls, topic, lambda data: None, Q.to_ros(self.qos), raw=True,
                                                                     event_callbacks=events, callback_group=self._part.reader.group)
        except BaseException:
            release(self._part)
            raise
        self._part.add(self)
        log.info("ROS 2 topic %s (%s) subscribed in this process, %s", topic, self.ros_type, Q.describe(self.qos))

    def _incompatible_qos(self, info: Any) -> None:
        policy = getattr(getattr(info, "last_policy_kind", None), "name", "?")
        _limited.warning(f"qos:{self.topic}:{policy}", "ROS 2 topic %s: a ROS 2 publisher's QoS is incompatible with this subscription's %s "
                         "on policy %s; no messages flow between them", self.topic, Q.describe(self.qos), policy)

    def deliver(self, data: bytes) -> None:
        """On the reader thread: decode, queue, wake. Nothing raised here stops the reader."""
        try:
            msg = self.codec.deserialize(self.msg_cls, data)
        except CdrError as exc:
            self.rejected += 1
            _limited.warning(f"cdr:{self.topic}", "ROS 2 topic %s: a malformed %s sample (%d bytes) dropped (%d so far): %s",
                             self.topic, self.ros_type, len(data), self.rejected, exc)
            return
        self.arrive(time.time_ns(), msg, "ros2")

    def writer_pids(self) -> list[int]:
        """ROS 2 publishers have no pid here: 0 per publisher on the graph (counted as alive)."""
        try:
            return [0] * self._part.node.count_publishers(self.topic)
        except Exception:  # noqa: BLE001 - closed
            return []

    def close(self) -> None:
        # After this returns the reader thread calls ``notify`` no more (see emos.transport.arrivals).
        if not self.close_arrivals():
            return
        self._part.remove(self)
        try:
            self._part.node.destroy_subscription(self.rclpy_sub)
        except Exception as exc:  # noqa: BLE001 - the node may be gone already
            log.debug("ROS 2 topic %s: destroying the subscription: %s", self.topic, exc)
        release(self._part)
