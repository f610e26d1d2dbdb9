"""A run's topics, live in Foxglove, over the Foxglove WebSocket protocol (``foxglove-sdk``).

How each topic is offered:

* types shared with ROS 2 go as ROS 2 channels: message encoding ``cdr``, schema ``ros2msg``
  with the full definition, named ``sensor_msgs/msg/LaserScan`` etc. Foxglove's 3D, Image, Map
  and Plot panels read sensor_msgs/LaserScan, Image, CompressedImage, PointCloud2,
  nav_msgs/OccupancyGrid, Path, Odometry and geometry_msgs/PoseStamped natively, with the ROS
  field names users already know. The bytes are those of :mod:`emos.interop.ros2_cdr`, the same
  as in our MCAP recordings, so a layout built on a live robot works on a recording and for a
  ROS 2 robot's data. One converter, instead of a second mapping to Foxglove's own schemas.
* ``tf2_msgs/TFMessage`` (``/tf``, ``/tf_static``) goes as ROS 2 cdr like the rest: Foxglove
  builds its frame tree from it. Topics of single ``geometry_msgs/TransformStamped`` messages go
  as ``foxglove.FrameTransforms`` (the SDK's schema, which Foxglove documents as a transform
  source for its 3D and Image panels), one transform becoming a one-element list.
* any other type (our own packages) goes as JSON, shown by the Raw Messages panel; arrays of
  more than ``MAX_JSON_ARRAY`` elements are replaced by a note of their dtype and shape.

Messages are converted only for channels a client subscribed to (``Channel.has_sinks``), so an
idle bridge costs one read per message.

Who may connect: clients reach the SDK's server only through :class:`HandshakeGate`
(:mod:`emos.interop.foxglove_gate`), which checks the browser ``Origin`` against an allow-list and,
when one is set, a token; a bridge on a non-loopback host requires a token.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Iterable
from typing import Any

import attrs
import numpy as np

from emos.hosts import is_loopback
from emos.interop.foxglove_gate import HandshakeGate, make_token, private_loopback_address
from emos.interop.ros2_cdr import DEFAULT_DISTRIBUTION, NotShared, codec_for
from emos.interop.tap import RunWatch, TopicTap
from emos.msgs import codec
from emos.msgs.geometry import TransformStamped
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext

log = logging.getLogger("emos.interop")
# Errors that repeat with every message: the first at once, then one counted line per topic per 10 s.
_limited = RateLimitedLog(log, interval=10.0)

MAX_JSON_ARRAY = 4096


def _foxglove() -> Any:
    try:
        import foxglove
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("the Foxglove bridge needs foxglove-sdk: pip install 'emos[ecosystem]'") from exc
    return foxglove


def to_json(msg: Any) -> Any:
    """A message as JSON-able builtins, with big arrays summarised."""
    if attrs.has(type(msg)):
        return {f.name: to_json(getattr(msg, f.name)) for f in attrs.fields(type(msg))}
    if isinstance(msg, np.ndarray):
        if msg.size > MAX_JSON_ARRAY:
            return f"<{msg.dtype} array {tuple(msg.shape)} not shown>"
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [to_json(v) for v in msg]
    return msg


class _Route:
    """One topic's channel and how its messages are turned into what the channel carries."""

    __slots__ = ("channel", "kind", "cls")

    def __init__(self, channel: Any, kind: str, cls: type):
        self.channel, self.kind, self.cls = channel, kind, cls


class FoxgloveBridge:
    """Serves a run's topics (all, or the given names/wildcards) on a Foxglove WebSocket server.

    ``port=0`` picks a free port (see :attr:`port`). ``use_waker`` makes :meth:`wait` sleep until
    a message arrives; a component polling at its loop rate passes ``False``. ``token``: ``None``,
    a string, or ``"auto"`` (a random one, see :attr:`token`), required of every client; it is
    mandatory when ``host`` is not a loopback address. ``allow_origins``: browser origins allowed
    besides :data:`~emos.interop.foxglove_gate.DEFAULT_ORIGINS`.
    """

    def __init__(self, ctx: RunContext, host: str = "127.0.0.1", port: int = 8765, topics: Iterable[str] | None = None,
                 exclude: Iterable[str] | None = None, distribution: str = DEFAULT_DISTRIBUTION, use_waker: bool = True,
                 name: str = "EMOS", token: str | None = None, allow_origins: Iterable[str] = ()):
        self.token = make_token(token)
        if self.token is None and not is_loopback(host):
            raise ValueError(f"Foxglove bridge: host {host!r} is not a loopback address, so every machine that reaches it "
                             "would get every topic (camera frames included): set a token ('auto' makes one)")
        fg = _foxglove()
        self._fg = fg
        self.ros2 = codec_for(distribution)
        self.context = fg.Context()
        self.routes: dict[str, _Route] = {}
        self.errors: dict[str, int] = {}
        self.sent: dict[str, int] = {}
        self.gate: HandshakeGate | None = None
        self.server: Any = None
        # Few messages queued per topic: a viewer wants the newest, not a backlog.
        self.tap = TopicTap(ctx, topics, exclude, queue_size=16, use_waker=use_waker)
        try:
            self.server = self._start_server(fg, name)
            self.gate = HandshakeGate(host, port, (self._inner, int(self.server.port)), allow_origins, self.token)
        except Exception as exc:
            self._stop_server()
            self.tap.close()
            if isinstance(exc, ValueError):
                raise
            raise OSError(f"Foxglove bridge: cannot serve on {host}:{port}: {exc}") from exc
        self.host = host
        self._add_routes(self.tap.subs)
        log.info("Foxglove bridge on ws://%s:%d serving %d topics%s", host, self.port, len(self.routes),
                 " (token required)" if self.token else "")

    def _start_server(self, fg: Any, name: str) -> Any:
        """The SDK's server, on a random private loopback address (see foxglove_gate for why)."""
        self._inner = "127.0.0.1"
        for _ in range(3):
            addr = private_loopback_address()
            try:
                server = fg.start_server(name=name, host=addr, port=0, context=self.context)
            except Exception as exc:  # a system where only 127.0.0.1 is configured
                log.debug("Foxglove bridge: cannot listen on %s: %s", addr, exc)
                continue
            self._inner = addr
            return server
        return fg.start_server(name=name, host="127.0.0.1", port=0, context=self.context)

    def _stop_server(self) -> None:
        if self.server is not None:
            server, self.server = self.server, None
            server.stop()

    @property
    def port(self) -> int:
        """The port clients connect to (the gate's)."""
        assert self.gate is not None
        return self.gate.port

    def url(self, with_token: bool = True) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}/" + (f"?token={self.token}" if self.token and with_token else "")

    def _add_routes(self, topics: Iterable[str]) -> None:
        for topic in topics:
            cls = self.tap.types[topic]
            self.routes[topic] = self._route(topic, cls)

    def _route(self, topic: str, cls: type) -> _Route:
        fg = self._fg
        if cls is TransformStamped:
            from foxglove.channels import FrameTransformsChannel

            return _Route(FrameTransformsChannel(topic, context=self.context), "tf", cls)
        try:
            ros_type = self.ros2.ros_type(cls)
        except NotShared:
            return _Route(fg.Channel(topic, message_encoding="json", context=self.context), "json", cls)
        schema = fg.Schema(name=ros_type, encoding="ros2msg", data=self.ros2.message_definition(cls).encode())
        return _Route(fg.Channel(topic, schema=schema, message_encoding="cdr", context=self.context), "cdr", cls)

    def wait(self, timeout: float) -> None:
        self.tap.wait(timeout)

    def step(self) -> int:
        """Forward what arrived since the last call; returns how many messages were sent."""
        self._add_routes(self.tap.discover())
        sent = 0
        for topic, stamp, frame in self.tap.take():
            route = self.routes[topic]
            if not route.channel.has_sinks():
                continue
            try:
                self._send(route, frame, stamp)
            except Exception as exc:  # one bad message must not stop the viewer
                n = self.errors[topic] = self.errors.get(topic, 0) + 1
                _limited.error(f"forward:{topic}", "Foxglove bridge: topic %s not forwarded (%d so far): %s", topic, n, exc)
                continue
            sent += 1
            self.sent[topic] = self.sent.get(topic, 0) + 1
        return sent

    def _send(self, route: _Route, frame: Any, stamp: int) -> None:
        msg = codec.decode(route.cls, frame)
        if route.kind == "cdr":
            route.channel.log(self.ros2.serialize(msg), log_time=stamp)
        elif route.kind == "tf":
            route.channel.log(self._frame_transforms(msg), log_time=stamp)
        else:
            route.channel.log(to_json(msg), log_time=stamp)

    def _frame_transforms(self, msg: TransformStamped) -> Any:
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3

        t, r = msg.transform.translation, msg.transform.rotation
        return FrameTransforms(transforms=[FrameTransform(
            timestamp=Timestamp(sec=msg.header.stamp.sec, nsec=msg.header.stamp.nanosec),
            parent_frame_id=msg.header.frame_id, child_frame_id=msg.child_frame_id,
            translation=Vector3(x=t.x, y=t.y, z=t.z), rotation=Quaternion(x=r.x, y=r.y, z=r.z, w=r.w),
        )])

    def serve(self, should_stop: Any, progress: Any = None, progress_every: float = 2.0) -> None:
        """Forward until ``should_stop()`` (the ``emos viz`` loop)."""
        next_report = time.monotonic() + progress_every
        alive = RunWatch(self.tap.ctx)
        while not should_stop():
            if not alive():
                log.info("Foxglove bridge: the system stopped")
                return
            self.wait(0.1)
            self.step()
            if progress is not None and time.monotonic() >= next_report:
                next_report = time.monotonic() + progress_every
                progress(f"Foxglove bridge {self.url(with_token=False)}: {len(self.routes)} topics; sent "
                         + ("  ".join(f"{t} {n}" for t, n in sorted(self.sent.items())) or "nothing yet (no client subscribed)"))

    def close(self) -> None:
        try:
            self._stop_server()  # the SDK server first, then the gate in front of it
            if self.gate is not None:
                self.gate.close()
        finally:
            for route in self.routes.values():
                try:
                    route.channel.close()
                except Exception as exc:  # a channel the server already dropped
                    log.debug("Foxglove bridge: closing %s: %s", route.channel.topic, exc)
            self.routes.clear()
            self.tap.close()
