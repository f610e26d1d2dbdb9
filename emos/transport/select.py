"""The transport interface a node talks to, and the choice of implementation per topic.

Like the middleware layer under a ROS 2 node, a node never builds shared-memory rings or Zenoh
declarations itself: it asks :func:`open_publisher` / :func:`open_subscriber` for a topic and
gets an object of the small interface below. Three implementations:

* ``shm`` (the default and the fast path): :class:`emos.transport.pubsub.Publisher` and
  ``Subscriber`` themselves, returned unwrapped, so local topics cost exactly what they did.
* ``zenoh``: :mod:`emos.transport.zenoh_net`, for topics that cross hosts.
* ``ros2``: :mod:`emos.interop.ros2.direct`, the topic on the ROS 2 graph from the component's
  own process (rclpy), without the run's ROS 2 bridge; only when a topic asks for it.

The choice, per topic: ``Topic(..., transport="zenoh")`` or ``"shm"`` in the recipe pins it;
the default ``"auto"`` follows the run option ``$EMOS_NET_TOPICS`` (``all``, or a comma
separated list of topic names), which ``emos run --net-topics`` sets. Nothing marked, nothing
changes.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, Protocol

from emos.transport.context import RunContext

ENV_NET_TOPICS = "EMOS_NET_TOPICS"
ENV_NET_SERVICES = "EMOS_NET_SERVICES"  # services and actions shared over Zenoh: see emos.transport.zenoh_rpc
TRANSPORTS = ("auto", "shm", "zenoh", "ros2")


class TopicPublisher(Protocol):
    topic: str

    def publish(self, msg: Any) -> int: ...
    def close(self) -> None: ...


class TopicSubscriber(Protocol):
    """What a node reads a topic through. ``take_raw`` gives ``(stamp_ns, payload, publisher)``,
    a payload turned into its message by :func:`payload_decoder`; the node learns of news from
    the waker it passed in."""

    topic: str
    dropped: int

    def take_raw(self) -> list[tuple[int, Any, str]]: ...
    def latest_raw(self) -> tuple[int, Any, str] | None: ...
    def has_news(self) -> bool: ...
    def writer_pids(self) -> list[int]: ...
    def close(self) -> None: ...


def payload_decoder(sub: Any, msg_type: type) -> Callable[[Any], Any]:
    """How a node turns ``sub``'s ``take_raw`` payloads into messages: as they are for a
    subscriber that ``decodes_on_arrival`` (Zenoh: each body was decoded, and one that did not
    decode dropped with a log line, before it was queued), else :func:`emos.msgs.codec.decode`
    of ``msg_type`` (shared memory: the ring's writer is trusted, and a message is decoded only
    when the node uses it)."""
    if getattr(sub, "decodes_on_arrival", False):
        return _as_is
    from functools import partial

    from emos.msgs import codec

    return partial(codec.decode, msg_type)


def _as_is(message: Any) -> Any:
    return message


def use_network(zenoh_config: str | None = None, topics: str | list[str] | None = None, services: str | list[str] | None = None, group: str | None = None) -> None:
    """The recipe's way to what ``emos run --zenoh CONFIG --net-topics ... --net-services ...``
    does; call it before ``Launcher.bringup()`` (component processes inherit it).

    ``topics`` / ``services``: ``"all"`` or names; ``group`` keeps robots on one network apart.
    Everything is checked here, so a typo fails before anything starts."""
    from emos.transport.zenoh_config import ENV_ZENOH_CONFIG
    from emos.transport.zenoh_net import ENV_NET_GROUP, net_group

    def names(value: str | list[str], what: str) -> str:
        if isinstance(value, str):
            return value
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise TypeError(f"use_network: {what} must be 'all' or a list of names, got {value!r}")
        return ",".join(value)

    if zenoh_config is not None:
        path = os.path.abspath(os.path.expanduser(zenoh_config))
        if not os.path.isfile(path):
            raise FileNotFoundError(f"use_network: Zenoh configuration file {zenoh_config!r} does not exist")
        os.environ[ENV_ZENOH_CONFIG] = path
    if group is not None:
        previous = os.environ.get(ENV_NET_GROUP)
        os.environ[ENV_NET_GROUP] = group
        try:
            net_group()
        except ValueError as exc:
            if previous is None:
                os.environ.pop(ENV_NET_GROUP)
            else:
                os.environ[ENV_NET_GROUP] = previous
            raise ValueError(f"use_network: group: {exc}") from None
    if topics is not None:
        value = names(topics, "topics")
        previous = os.environ.get(ENV_NET_TOPICS)
        os.environ[ENV_NET_TOPICS] = value
        try:
            net_topics_option()  # raises on a bad name
        except ValueError:
            if previous is None:
                os.environ.pop(ENV_NET_TOPICS)
            else:
                os.environ[ENV_NET_TOPICS] = previous
            raise
    if services is not None:
        os.environ[ENV_NET_SERVICES] = names(services, "services")


def use_ros2(topics: str | list[str] | None = None, domain_id: int | None = None) -> str:
    """The recipe's way to what ``emos run --ros2 --ros2-topics ... --ros-domain-id N`` does: the
    run gets a supervised ROS 2 bridge (emos.interop.ros2.bridge) for ``topics`` (``"all"``, the
    default, or names / wildcards) on ROS 2 domain ``domain_id`` (default ``$ROS_DOMAIN_ID``, else
    0). Call it before ``Launcher.bringup()``. Checked here: a bad name, a bad domain, or no ROS 2
    installed fails at once (the error says what to install). Returns which ROS 2 is used, in one line."""
    from emos.interop.ros2 import env
    from emos.interop.ros2.options import ENV_ROS2, ENV_ROS2_DOMAIN, ENV_ROS2_TOPICS, check_domain, parse_topics

    names = parse_topics(topics, "use_ros2: topics")
    domain = check_domain(domain_id)
    install = env.require()
    os.environ[ENV_ROS2] = "1"
    os.environ[ENV_ROS2_TOPICS] = ",".join(names) or "all"
    if domain is not None:
        os.environ[ENV_ROS2_DOMAIN] = str(domain)
    return install.describe()


def net_topics_option() -> tuple[bool, frozenset[str]]:
    """``(all topics, named topics)`` from ``$EMOS_NET_TOPICS``."""
    raw = os.environ.get(ENV_NET_TOPICS, "").strip()
    if not raw:
        return False, frozenset()
    if raw == "all":
        return True, frozenset()
    from emos.io.topic import normalize_topic_name

    try:
        names = frozenset(normalize_topic_name(part) for part in raw.split(",") if part.strip())
    except ValueError as exc:
        raise ValueError(f"${ENV_NET_TOPICS} must be 'all' or topic names separated by ',': {exc}") from None
    return False, names


def transport_of(topic_name: str, declared: str = "auto") -> str:
    """``"shm"``, ``"zenoh"`` or ``"ros2"`` for a topic declared with ``transport=declared``."""
    if declared not in TRANSPORTS:
        raise ValueError(f"topic {topic_name!r}: transport must be one of {TRANSPORTS}, got {declared!r}")
    if declared != "auto":
        return declared
    every, named = net_topics_option()
    return "zenoh" if every or topic_name in named else "shm"


def open_publisher(ctx: RunContext, topic: Any, publisher_id: str | None = None, depth: int = 10) -> TopicPublisher:
    """A publisher for ``topic`` (an :class:`emos.io.topic.Topic`) on its transport."""
    chosen = transport_of(topic.name, getattr(topic, "transport", "auto"))
    if chosen == "ros2":
        from emos.interop.ros2.direct import Ros2Publisher

        return Ros2Publisher(ctx, topic.name, topic.msg_type, publisher_id=publisher_id, qos=topic.qos_profile)
    if chosen == "zenoh":
        from emos.transport.zenoh_net import ZenohPublisher

        return ZenohPublisher(topic.name, topic.msg_type, publisher_id=publisher_id, transient_local=topic.qos_profile.transient_local, depth=depth)
    from emos.transport.pubsub import Publisher

    # A volatile topic's big messages may reuse recent ring slots (ring.py, "Recent slots"); a
    # transient-local one keeps its whole history for subscribers that join later.
    return Publisher(ctx, topic.name, topic.msg_type, publisher_id=publisher_id, depth=depth, reuse_recent=not topic.qos_profile.transient_local)


def open_subscriber(ctx: RunContext, topic: Any, waker: Any = None, queue_size: int = 10, transient_local: bool = False,
                    node_name: str | None = None) -> TopicSubscriber:
    """A subscriber for ``topic`` on its transport; ``waker`` (the node's) is woken on news.
    ``node_name``: whose subscriber (a ``ros2`` topic's node is named after it)."""
    chosen = transport_of(topic.name, getattr(topic, "transport", "auto"))
    if chosen == "ros2":
        from emos.interop.ros2.direct import Ros2Subscriber

        return Ros2Subscriber(ctx, topic.name, topic.msg_type, notify=waker.poke if waker is not None else None, queue_size=queue_size,
                              qos=topic.qos_profile, node_name=node_name)
    if chosen == "zenoh":
        from emos.transport.zenoh_net import ZenohSubscriber

        notify: Callable[[], None] | None = waker.poke if waker is not None else None
        return ZenohSubscriber(topic.name, topic.msg_type, notify=notify, queue_size=queue_size, transient_local=transient_local)
    from emos.transport.pubsub import Subscriber

    return Subscriber(ctx, topic.name, topic.msg_type, waker=waker, queue_size=queue_size, transient_local=transient_local)


def open_server_bridge(ctx: RunContext, server: Any) -> Any | None:
    """A Zenoh queryable in front of a started service or action server, if the run shares it
    over the network (``$EMOS_NET_SERVICES``); ``None`` otherwise. Its ``close()`` is synchronous
    (the servers' is a coroutine: the node awaits what close() returns)."""
    if not os.environ.get(ENV_NET_SERVICES, "").strip():
        return None
    from emos.core.services import ActionServer
    from emos.transport.zenoh_rpc import NetServiceBridge, shared_over_network

    if not shared_over_network(server.name):
        return None
    return NetServiceBridge(ctx, server.name, "action" if isinstance(server, ActionServer) else "service")


def list_topics(ctx: RunContext, network: bool | None = None) -> dict[str, dict[str, Any]]:
    """Topics of this run (shared memory) and, if ``network`` (default: when the run uses
    Zenoh), those of every host in the Zenoh group, each marked with its ``transport``."""
    from emos.transport import pubsub

    topics = {name: {**info, "transport": "shm"} for name, info in pubsub.list_topics(ctx).items()}
    if network is None:
        network = bool(os.environ.get(ENV_NET_TOPICS) or os.environ.get("EMOS_ZENOH_CONFIG"))
    if network:
        from emos.transport.zenoh_net import list_topics as net_list

        for name, info in net_list().items():
            topics.setdefault(name, info)
    return topics
