"""Topics across hosts over Zenoh: the network implementation of the transport interface.

A topic marked for the network (see :mod:`emos.transport.select`) is published to and
subscribed from the Zenoh key expression ``emos/<group>/<topic>`` (``/scan`` of group
``lab`` is ``emos/lab/scan``), each sample one frame of :mod:`emos.transport.netframe`: the
same msgpack + raw-array encoding as a shared-memory ring, behind a small header naming the
type fingerprint and the publisher (a large message puts that header in the sample's
attachment and its arrays in the payload, so an array received as ``bytes`` is forwarded with
no copy). ``<group>`` (``$EMOS_NET_GROUP``, default ``default``) keeps robots that share a
network apart.

One Zenoh session per process and configuration file, opened on first use and shared by every
topic of the process. Its mode (peer or client), endpoints and scouting come from the Zenoh
configuration file (``$EMOS_ZENOH_CONFIG``, set by ``emos run --zenoh CONFIG``); without one,
the session stays on loopback and meets the other sessions of this host only (see
:mod:`emos.transport.zenoh_config`, which builds every session's configuration).

Zenoh delivers samples on its own threads. A subscriber checks and decodes each one there
(magic, lengths, type fingerprint, then the body; anything that fails is dropped with a
rate-limited warning naming the key), appends the message to a bounded queue (``queue_size``,
oldest dropped and counted) and calls its ``notify`` (the node's waker: one byte to the FIFO
its uvloop watches). The node then takes the decoded messages on its own thread, as it reads a
ring. Decoding on arrival costs a message the reader skips about 2 us, and is cheaper for every
message it uses: the reader runs it straight after a wake-up, which is when Python code runs
slowest (an 8 B ping-pong: take and decode 18 us on the reader, against a decode of 8-10 us
on Zenoh's thread and a take of 3; docs/benchmarks-history.md, "Decoding on Zenoh's thread").

Publishers also declare a liveliness token ``emos/<group>/<topic>/_pub_/<type>/<publisher>``,
so :func:`list_topics` can discover the topics of every host in the group.
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

from emos.errors import TransportError
from emos.msgs.registry import canonical_name
from emos.ratelimit import RateLimitedLog
from emos.transport import zenoh_config
from emos.transport.arrivals import ArrivalQueue
from emos.transport.context import encode_name
from emos.transport.netframe import SPLIT_MAGIC, BadFrame, FrameWriter, SplitPayload, encode_framed, read_frame, read_message
from emos.transport.zenoh_config import ENV_ZENOH_CONFIG

log = logging.getLogger("emos.transport.zenoh")
ENV_NET_GROUP = "EMOS_NET_GROUP"
DEFAULT_GROUP = "default"
KEY_ROOT = "emos"
_PUB_MARK = "_pub_"
_GROUP_RE = re.compile(r"^[A-Za-z0-9_\-]+$")
_warn = RateLimitedLog(log, interval=10.0)


class NetUnavailable(TransportError, RuntimeError):
    """A topic was marked for the network but Zenoh cannot be used."""


def _zenoh() -> Any:
    try:
        import zenoh
    except ImportError:
        raise NetUnavailable("topics over the network need Zenoh: pip install 'emos[net]' (eclipse-zenoh)") from None
    return zenoh


def net_group() -> str:
    group = os.environ.get(ENV_NET_GROUP, DEFAULT_GROUP)
    if not _GROUP_RE.match(group):
        raise ValueError(f"${ENV_NET_GROUP} must be letters, digits, '_' or '-', got {group!r}")
    return group


def topic_key(topic: str, group: str | None = None) -> str:
    """The Zenoh key expression of ``topic``: ``emos/<group>/<topic without its leading '/'>``."""
    name = topic.strip("/")
    if not name or any(ch in name for ch in "*$?#@") or "//" in name:
        raise ValueError(f"topic {topic!r} cannot be a Zenoh key expression (no '*', '$', '?', '#', '@' or empty parts)")
    return f"{KEY_ROOT}/{group or net_group()}/{name}"


# ------------------------------------------------------------------------------------ sessions
_sessions: dict[tuple[int, str], Any] = {}  # (pid, config path): a forked child opens its own
_sessions_lock = threading.Lock()
_registrations: dict[tuple[int, str], Any] = {}  # a loopback session's registration (zenoh_config.open_loopback)


def session(config_path: str | None = None) -> Any:
    """This process's Zenoh session for ``config_path`` (default ``$EMOS_ZENOH_CONFIG``; none:
    loopback only, see :mod:`emos.transport.zenoh_config`)."""
    path = config_path if config_path is not None else os.environ.get(ENV_ZENOH_CONFIG, "")
    key = (os.getpid(), path)
    with _sessions_lock:
        sess = _sessions.get(key)
        if sess is None or sess.is_closed():
            zenoh = _zenoh()
            if key in _registrations:  # closed by someone else: its endpoint answers no more
                zenoh_config.unregister(_registrations.pop(key))
            if not path:
                sess, _registrations[key] = zenoh_config.open_loopback(zenoh)
            else:
                sess = _open_file(zenoh, path)
                log.info("Zenoh session %s opened (%s)", sess.info.zid(), path)
            _sessions[key] = sess
        return sess


def _open_file(zenoh: Any, path: str) -> Any:
    conf = _load_config(zenoh, path)
    zenoh_config.warn_if_exposed(conf, path)
    try:
        return zenoh.open(conf)
    except Exception as exc:  # zenoh.ZError
        # Every process of a run reads the same file; only the first can bind a fixed
        # listening port. The others listen on a port of the kernel's choosing and still
        # reach the other hosts through the configured ``connect`` endpoints.
        ephemeral = _ephemeral_listen(zenoh, path) if "Address already in use" in str(exc) else None
        if ephemeral is None:
            raise
        log.info("Zenoh: %s; this process listens on %s instead", str(exc).split(" at ")[0], ephemeral.get_json("listen/endpoints"))
        return zenoh.open(ephemeral)


_load_config = zenoh_config.load_config  # the file's configuration (its doc says what EMOS changes)


def _ephemeral_listen(zenoh: Any, path: str) -> Any | None:
    """The configuration of ``path`` with every fixed listening port replaced by 0, or None."""
    if not path:
        return None
    conf = _load_config(zenoh, path)
    endpoints = json.loads(conf.get_json("listen/endpoints"))
    if not isinstance(endpoints, list) or not endpoints:
        return None
    conf.insert_json5("listen/endpoints", json.dumps([re.sub(r":\d+(?=($|[?#]))", ":0", str(e), count=1) for e in endpoints]))
    return conf


def close_sessions() -> None:
    """Close every session of this process (end of a run, tests)."""
    with _sessions_lock:
        for (pid, _), sess in _sessions.items():
            if pid != os.getpid():
                continue  # inherited through fork: its threads are not ours to stop
            try:
                sess.close()
            except Exception as exc:  # noqa: BLE001 - closing must go on for the others
                log.debug("closing a Zenoh session: %s", exc)
        _sessions.clear()
        _registrations.clear()
        zenoh_config.unregister_all()


# Zenoh (1.10) can deadlock a session when one thread declares or undeclares an entity while
# another waits for a reply from the admin space (@/...): the declaration holds a routing mutex
# the reply's delivery needs and waits for the routing RwLock the delivery holds, both threads in
# Rust, out of pytest-timeout's reach (a suite run hung in declare_advanced_publisher beside a
# SecurityWatch check of the same session). Our declarations and our admin queries
# (emos.security.watch) take turns on this lock; nothing else needs it.
ROUTING_TURNS = threading.RLock()


# ------------------------------------------------------------------------------------ endpoints
def _latched_publisher(zenoh: Any, sess: Any, key: str, depth: int) -> Any:
    """A publisher that keeps its last ``depth`` samples for subscribers that join later
    (TRANSIENT_LOCAL): Zenoh's advanced publisher, whose cache answers the history query of an
    advanced subscriber (:func:`_latched_subscriber`), including one that appears after the put.

    Samples carry sequence numbers (miss detection, with no heartbeat), not timestamps: that
    needs nothing in the user's Zenoh configuration (timestamps need ``timestamping`` enabled),
    and a subscriber that gets a sample both live and from the cache delivers it once."""
    from zenoh import ext

    depth = max(int(depth), 1)
    return ext.declare_advanced_publisher(
        sess, key, congestion_control=zenoh.CongestionControl.DROP, cache=ext.CacheConfig(depth),
        sample_miss_detection=ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=None), publisher_detection=True,
    )


def _latched_subscriber(sess: Any, key: str, depth: int, callback: Callable[[Any], None]) -> Any:
    """A subscriber that, on declaration and whenever a latched publisher appears, asks the
    publishers' caches for their last ``depth`` samples; replies and live samples reach the same
    ``callback``. Missed samples are not recovered (no retransmission): as on a ring, a reader
    that falls behind loses the oldest, it is not replayed."""
    from zenoh import ext

    history = ext.HistoryConfig(detect_late_publishers=True, max_samples=max(int(depth), 1))
    return ext.declare_advanced_subscriber(sess, key, callback, history=history)


class ZenohPublisher:
    """Publishes one topic's messages to its key expression.

    ``transient_local`` (the topic's QoS durability): the publisher keeps its last ``depth``
    messages, and a subscriber that is TRANSIENT_LOCAL too receives them when it joins, as from
    a ring. As in ROS 2, both sides must ask for it."""

    def __init__(self, topic: str, msg_cls: type, publisher_id: str | None = None, config_path: str | None = None, group: str | None = None,
                 transient_local: bool = False, depth: int = 10):
        zenoh = _zenoh()
        self.topic, self.msg_cls = topic, msg_cls
        self.type_name = canonical_name(msg_cls)
        self.fingerprint: str = msg_cls._emos_fingerprint  # type: ignore[attr-defined]
        self.publisher_id = publisher_id or f"pid{os.getpid()}-{id(self):x}"
        self.key = topic_key(topic, group)
        self._frames = FrameWriter(self.fingerprint, self.publisher_id)
        sess = session(config_path)
        self.transient_local = transient_local
        token_key = f"{self.key}/{_PUB_MARK}/{encode_name(self.type_name)}/{encode_name(self.publisher_id)}"
        with ROUTING_TURNS:
            # RELIABLE + DROP: like a ring, a slow reader never blocks the writer.
            if transient_local:
                self._pub = _latched_publisher(zenoh, sess, self.key, depth)
            else:
                self._pub = sess.declare_publisher(self.key, congestion_control=zenoh.CongestionControl.DROP)
            self._token = sess.liveliness().declare_token(token_key)
        self.sent = 0

    def publish(self, msg: Any) -> int:
        if not isinstance(msg, self.msg_cls):
            from emos.transport.pubsub import TopicTypeError

            raise TopicTypeError(f"topic {self.topic!r} carries {self.type_name}, got {type(msg).__name__}")
        if self._pub is None:
            raise RuntimeError(f"topic {self.topic!r}: publisher {self.publisher_id!r} is closed")
        # Publishing is single-threaded per publisher (the node holds its lock), so one writer;
        # Zenoh copies the frame on put, so its buffer is free again when put returns.
        enc = encode_framed(msg, self._frames.header, None, FrameWriter.SMALL)  # a small message: its whole frame, stamped now
        if type(enc) is bytes:
            self._pub.put(enc)
        elif enc.array_bytes < FrameWriter.SPLIT:
            self._pub.put(self._frames.frame(enc, time.time_ns()))
        else:  # arrays as the payload, header in the attachment: no copy of an array held in bytes
            arrays, head = self._frames.split(enc, time.time_ns())
            self._pub.put(arrays, attachment=head)
        self.sent += 1
        return self.sent - 1

    def close(self) -> None:
        for thing in (self._token, self._pub):
            if thing is not None:
                try:
                    with ROUTING_TURNS:
                        thing.undeclare()
                except Exception as exc:  # noqa: BLE001 - the session may be gone already
                    log.debug("topic %s: undeclaring: %s", self.topic, exc)
        self._token = self._pub = None


class ZenohSubscriber(ArrivalQueue):
    """Receives one topic from every publisher on its key expression, on any host of the group.

    The same reading interface as :class:`emos.transport.pubsub.Subscriber` (``take_raw``,
    ``latest_raw``, ``has_news``, ``take``, ``latest``, ``close``), so a node reads either alike;
    ``take_raw``'s payloads are the messages themselves, already decoded (``decodes_on_arrival``,
    see :func:`emos.transport.select.payload_decoder`). ``notify`` is called (on a Zenoh thread)
    after each accepted message.

    Zenoh's thread checks the frame (:func:`read_frame`: magic, lengths, type fingerprint),
    decodes the body, and queues the message; anything that fails either step is dropped there
    with a rate-limited warning, and never wakes the reader. Why decode there rather than on the
    reader's thread: see the module doc. Zenoh's thread holds no lock while it wakes the reader,
    so the woken thread never waits for it.
    """

    decodes_on_arrival = True
    threaded_delivery = True  # Zenoh's threads deliver, holding the interpreter lock: a node must not spin (see Node)

    def __init__(self, topic: str, msg_cls: type, notify: Callable[[], None] | None = None, queue_size: int = 10, transient_local: bool = False, config_path: str | None = None, group: str | None = None):
        self.topic, self.msg_cls = topic, msg_cls
        self.fingerprint: str = msg_cls._emos_fingerprint  # type: ignore[attr-defined]
        self._fp = self.fingerprint.encode()
        self.key = topic_key(topic, group)
        ArrivalQueue.__init__(self, topic, queue_size, notify, _warn)
        self.rejected = 0  # payloads that were not a frame, or not a decodable message, of our type
        self.undecodable = 0  # of those, well-framed ones whose body did not decode (as Subscriber's)
        # A queued message's arrays are read-only views of the bytes Zenoh delivered.
        self._publishers: set[str] = set()
        self.transient_local = transient_local
        sess = session(config_path)
        with ROUTING_TURNS:
            if transient_local:
                # The publishers' cached messages arrive as replies, through _on_sample like live
                # ones: checked and decoded there exactly as live ones.
                self._sub = _latched_subscriber(sess, self.key, self.queue_size, self._on_sample)
            else:
                self._sub = sess.declare_subscriber(self.key, self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        """On a Zenoh thread: check the frame, decode, queue, wake. Nothing raised here may
        escape (it would be lost in Zenoh's thread and the subscriber would look alive while deaf)."""
        try:
            head = sample.attachment
            if head is None:  # a whole frame: checked and decoded in one call
                stamp, pub, msg = read_message(sample.payload.to_bytes(), self._fp, self.msg_cls)
            else:  # a large message: arrays in the payload (see emos.transport.netframe)
                # The header first: a bad one costs no copy of the arrays.
                stamp, pub, meta = read_frame(head.to_bytes(), self._fp, SPLIT_MAGIC)
                msg = SplitPayload(meta, sample.payload.to_bytes()).decode(self.msg_cls)
        except BadFrame as exc:
            self._reject(str(sample.key_expr), exc)
            return
        except Exception as exc:  # noqa: BLE001 - DecodeError, or anything a forged body provokes
            # Anyone on the network can send a well-framed lie: the body is checked by decoding it.
            self.undecodable += 1
            self._reject(str(sample.key_expr), exc)
            return
        if pub not in self._publishers:
            self._publishers.add(pub)
        self.arrive(stamp, msg, pub)

    def _reject(self, key: str, exc: BaseException) -> None:
        self.rejected += 1
        _warn.warning(
            f"reject:{self.key}", "topic %s: dropping a payload on key %s that is not a %s (%d so far): %s: %s",
            self.topic, key, canonical_name(self.msg_cls), self.rejected, type(exc).__name__, exc,
        )

    def publishers(self) -> list[str]:
        return sorted(self._publishers)

    def writer_pids(self) -> list[int]:
        """Remote processes have no pid here: 0 per publisher seen (counted as alive)."""
        return [0] * len(self._publishers)

    def close(self) -> None:
        # After this returns no Zenoh thread calls ``notify`` (see emos.transport.arrivals).
        self.close_arrivals()
        sub, self._sub = self._sub, None
        if sub is not None:
            try:
                with ROUTING_TURNS:
                    sub.undeclare()
            except Exception as exc:  # noqa: BLE001 - the session may be gone already
                log.debug("topic %s: undeclaring: %s", self.topic, exc)


# ------------------------------------------------------------------------------------ discovery
def list_topics(group: str | None = None, config_path: str | None = None, timeout: float = 1.0) -> dict[str, dict[str, Any]]:
    """Topics published over Zenoh in ``group`` by any host: ``{topic: {"type", "publishers"}}``."""
    from emos.transport.context import decode_name

    group = group or net_group()
    root = f"{KEY_ROOT}/{group}/"
    topics: dict[str, dict[str, Any]] = {}
    replies = session(config_path).liveliness().get(f"{root}**", timeout=timeout)
    for reply in replies:
        if reply.ok is None:
            continue
        key = str(reply.ok.key_expr)
        parts = key[len(root):].split("/")
        if len(parts) < 4 or parts[-3] != _PUB_MARK:
            continue
        topic = "/" + "/".join(parts[:-3])
        entry = topics.setdefault(topic, {"type": decode_name(parts[-2]).lstrip("/"), "publishers": [], "transport": "zenoh"})
        pub = decode_name(parts[-1]).lstrip("/")
        if pub not in entry["publishers"]:
            entry["publishers"].append(pub)
    return topics
