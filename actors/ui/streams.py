"""From topics to browsers without ever slowing a topic down.

The component hands every received message to the topic's hub on its event loop; a hub only
stores it (O(1), no encoding). Each connected page has one sender task that takes from the hubs
what that page is ready for:

* log hubs (text, numbers) keep the last ``history`` messages; a page that falls further behind
  skips the oldest and is told how many it missed;
* latest hubs (poses, paths, other messages) keep one value, sent at most ``pose_rate`` times a
  second per page;
* frame hubs (images, maps, audio) keep one message and encode it in a worker thread only when a
  page can take a frame. A page may have ``frames_in_flight`` unconfirmed frames; whatever
  arrives meanwhile is dropped. So a slow page gets fewer frames, never a backlog, and nobody is
  encoded for when no page is open.

Binary frames are ``u32 header length | JSON header | payload`` (big endian length).
"""
from __future__ import annotations

import asyncio
import collections
import json
import logging
import struct
import time
from collections.abc import Callable
from concurrent.futures import Executor
from typing import Any

from emos.actors.ui import codecs
from emos.actors.ui.config import UIConfig
from emos.actors.ui.widgets import FRAME_KINDS, LOG_KINDS
from emos.ratelimit import RateLimitedLog

log = logging.getLogger("emos.ui")
# A message the page cannot show usually repeats with every frame: once, then counted per topic.
_encode_errors = RateLimitedLog(log, interval=10.0)

_LEN = struct.Struct(">I")


def stamp_ms(msg: Any, received_ns: int) -> float:
    """The message's header stamp (ms since the epoch) if it has one, else when it arrived."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is not None and (stamp.sec or stamp.nanosec):
        return stamp.sec * 1e3 + stamp.nanosec / 1e6
    return received_ns / 1e6


def binary_frame(header: dict[str, Any], payload: bytes) -> bytes:
    head = json.dumps(header, separators=(",", ":")).encode()
    return _LEN.pack(len(head)) + head + payload


class Client:
    """One connected page: what it has been sent, and what it has not yet confirmed."""

    def __init__(self, send_str: Callable[[str], Any], send_bytes: Callable[[bytes], Any], peer: str):
        self.send_str, self.send_bytes, self.peer = send_str, send_bytes, peer
        self.dirty = asyncio.Event()
        self.sent: dict[str, int] = collections.defaultdict(int)
        self.in_flight: dict[str, int] = collections.defaultdict(int)
        self.next_due: dict[str, float] = {}
        self.wake_pending: set[str] = set()
        self.frames_sent = 0

    def ack(self, topic: str) -> None:
        if self.in_flight.get(topic, 0) > 0:
            self.in_flight[topic] -= 1
        self.dirty.set()

    def wake_at(self, topic: str, when: float) -> None:
        """Look at ``topic`` again at loop time ``when`` (throttled latest-value widgets)."""
        if topic in self.wake_pending:
            return
        self.wake_pending.add(topic)

        def wake() -> None:
            self.wake_pending.discard(topic)
            self.dirty.set()

        asyncio.get_running_loop().call_at(when, wake)


class Hub:
    family = "latest"

    def __init__(self, topic: str, type_name: str, kind: str, config: UIConfig):
        self.topic, self.type_name, self.kind, self.config = topic, type_name, kind, config
        self.seq = 0
        self.clients: set[Client] = set()
        self.received = 0

    def push(self, msg: Any, received_ns: int) -> None:
        self.seq += 1
        self.received += 1
        self._store(msg, received_ns)
        for c in self.clients:
            c.dirty.set()

    def _store(self, msg: Any, received_ns: int) -> None:
        raise NotImplementedError

    async def send_to(self, client: Client, loop: asyncio.AbstractEventLoop, executor: Executor) -> None:
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        return {"topic": self.topic, "type": self.type_name, "kind": self.kind}

    def latest(self) -> dict[str, Any]:
        """The newest message as JSON for the API: ``{topic, seq, stamp, value}`` (value
        ``None`` before the first; long arrays cut, pictures as their size, not their pixels)."""
        msg = getattr(self, "msg", None)
        value = codecs.summarize(msg) if msg is not None else None
        return {"topic": self.topic, "type": self.type_name, "seq": self.seq, "stamp": getattr(self, "stamp", None), "value": value}


class LogHub(Hub):
    family = "log"

    def __init__(self, *args: Any):
        super().__init__(*args)
        self.items: collections.deque[tuple[int, float, Any]] = collections.deque(maxlen=self.config.history)

    def _store(self, msg: Any, received_ns: int) -> None:
        value = msg.data
        if self.kind == "number":
            value = float(value)
        elif self.type_name == "StreamingString":
            # Chunks of one streamed reply go into one bubble on the page, closed by ``done``.
            value = {"text": msg.data, "stream": bool(msg.stream), "done": bool(msg.done)}
        self.items.append((self.seq, stamp_ms(msg, received_ns), value))

    def latest(self) -> dict[str, Any]:
        seq, stamp, value = self.items[-1] if self.items else (self.seq, None, None)
        return {"topic": self.topic, "type": self.type_name, "seq": seq, "stamp": stamp, "value": value}

    async def send_to(self, client: Client, loop: asyncio.AbstractEventLoop, executor: Executor) -> None:
        last = client.sent[self.topic]
        if last >= self.seq or not self.items:
            return
        fresh = [item for item in self.items if item[0] > last]
        missed = max(0, fresh[0][0] - last - 1) if fresh else 0
        client.sent[self.topic] = self.seq
        await client.send_str(json.dumps({"op": "log", "topic": self.topic, "kind": self.kind, "missed": missed,
                                          "items": [[s, t, v] for s, t, v in fresh]}, allow_nan=False, default=str))


class LatestHub(Hub):
    """Poses, paths, booleans and any other message: the newest value, rate-limited per page."""

    def __init__(self, *args: Any):
        super().__init__(*args)
        self.msg: Any = None
        self.stamp = 0.0
        self._payload: tuple[int, str] | None = None

    def _store(self, msg: Any, received_ns: int) -> None:
        self.msg, self.stamp = msg, stamp_ms(msg, received_ns)

    def _encode(self) -> str:
        if self._payload is not None and self._payload[0] == self.seq:
            return self._payload[1]
        msg = self.msg
        if self.kind == "pose":
            value: Any = codecs.pose_of(msg)
        elif self.kind == "path":
            value = codecs.path_points(msg)
        elif self.kind == "bool":
            value = bool(msg.data)
        else:
            value = codecs.summarize(msg)
        text = json.dumps({"op": "latest", "topic": self.topic, "kind": self.kind, "seq": self.seq, "stamp": self.stamp,
                           "value": value}, default=str)
        self._payload = (self.seq, text)
        return text

    async def send_to(self, client: Client, loop: asyncio.AbstractEventLoop, executor: Executor) -> None:
        if client.sent[self.topic] >= self.seq or self.msg is None:
            return
        now = loop.time()
        due = client.next_due.get(self.topic, 0.0)
        if now < due:
            client.wake_at(self.topic, due)
            return
        client.next_due[self.topic] = now + 1.0 / self.config.pose_rate
        client.sent[self.topic] = self.seq
        await client.send_str(self._encode())


class FrameHub(Hub):
    """Images, maps and audio: encoded off the loop, only when a page can take a frame."""

    family = "frame"

    def __init__(self, *args: Any, overlay: bool = False):
        super().__init__(*args)
        self.overlay = overlay
        self.msg: Any = None
        self.stamp = 0.0
        self.encoded: tuple[int, bytes] | None = None  # (seq, binary frame)
        self._encoding = False
        self._encode_task: asyncio.Future[None] | None = None  # held: the loop keeps only weak references
        self.encoded_count = 0
        self.errors = 0

    def _store(self, msg: Any, received_ns: int) -> None:
        self.msg, self.stamp = msg, stamp_ms(msg, received_ns)

    def _encode(self, msg: Any, seq: int, stamp: float) -> bytes:
        header: dict[str, Any] = {"topic": self.topic, "kind": self.kind, "seq": seq, "stamp": stamp}
        if self.kind == "map":
            info = msg.info
            header.update(mime="image/png", width=int(info.width), height=int(info.height), resolution=float(info.resolution),
                          origin=[info.origin.position.x, info.origin.position.y, codecs.yaw_of(info.origin.orientation)],
                          overlay=self.overlay)
            return binary_frame(header, codecs.encode_grid(msg, overlay=self.overlay))
        if self.kind == "audio":
            header.update(mime="audio/wav")
            return binary_frame(header, codecs.encode_wav(msg))
        image = msg
        if self.type_name == "Detections":
            header["boxes"] = [[*map(float, b), str(label), float(s)] for b, label, s in zip(msg.boxes, msg.labels, msg.scores)]
            image = msg.image
            if image is None:
                raise ValueError(f"Detections on {self.topic} carry no image to draw them on")
        data, mime, w, h = codecs.encode_image_msg(image, self.config.jpeg_quality, self.config.max_image_side)
        header.update(mime=mime, width=w, height=h)
        return binary_frame(header, data)

    async def _encode_latest(self, loop: asyncio.AbstractEventLoop, executor: Executor) -> None:
        self._encoding = True
        msg, seq, stamp = self.msg, self.seq, self.stamp
        try:
            frame = await loop.run_in_executor(executor, self._encode, msg, seq, stamp)
            self.encoded = (seq, frame)
            self.encoded_count += 1
        except Exception as exc:
            self.errors += 1
            _encode_errors.error(self.topic, "[ui] cannot show %s (%s) on the page: %s (%d errors so far)", self.topic,
                                 self.type_name, exc, self.errors)
            self.encoded = (seq, b"")  # do not retry this message
        finally:
            self._encoding = False
            for c in self.clients:
                c.dirty.set()

    async def send_to(self, client: Client, loop: asyncio.AbstractEventLoop, executor: Executor) -> None:
        if self.msg is None or client.sent[self.topic] >= self.seq:
            return
        if client.in_flight[self.topic] >= self.config.frames_in_flight:
            return  # the page is busy: whatever arrives meanwhile is dropped for it
        if self.encoded is not None and self.encoded[0] > client.sent[self.topic] and self.encoded[1]:
            seq, frame = self.encoded
            client.sent[self.topic] = seq
            client.in_flight[self.topic] += 1
            client.frames_sent += 1
            await client.send_bytes(frame)
        elif self.encoded is not None and self.encoded[0] > client.sent[self.topic]:
            client.sent[self.topic] = self.encoded[0]  # that one failed to encode: skip it
        if (self.encoded is None or self.encoded[0] < self.seq) and not self._encoding:
            self._encode_task = asyncio.ensure_future(self._encode_latest(loop, executor))


def make_hub(topic: str, type_name: str, kind: str, config: UIConfig, overlay: bool = False) -> Hub:
    if kind in LOG_KINDS:
        return LogHub(topic, type_name, kind, config)
    if kind in FRAME_KINDS:
        return FrameHub(topic, type_name, kind, config, overlay=overlay)
    return LatestHub(topic, type_name, kind, config)


async def serve_client(client: Client, hubs: list[Hub], closed: asyncio.Event, executor: Executor) -> None:
    """The sender task of one page: wait for news, send what the page is ready for."""
    loop = asyncio.get_running_loop()
    for hub in hubs:
        hub.clients.add(client)
    client.dirty.set()
    try:
        while not closed.is_set():
            await client.dirty.wait()
            client.dirty.clear()
            for hub in hubs:
                await hub.send_to(client, loop, executor)
    finally:
        for hub in hubs:
            hub.clients.discard(client)


def now_ms() -> float:
    return time.time() * 1e3
