"""The receiving end of a subscriber whose messages arrive already decoded on another thread.

Zenoh's subscriber (:class:`emos.transport.zenoh_net.ZenohSubscriber`, decoded on Zenoh's
callback threads) and the ROS 2 one (:class:`emos.interop.ros2.direct.Ros2Subscriber`, decoded
on the reader thread) hand each message to the node the same way: a bounded queue of
``(stamp_ns, message, publisher)`` that drops the oldest when full, and a wake-up of the node's
waker. The rules that make that safe live here, once:

* the lock is held for an append or a drain, never while waking: the woken reader must never
  wait for the delivering thread, which needs the interpreter lock back after its wake-up write;
* after :meth:`ArrivalQueue.close_arrivals` returns, no delivering thread calls ``notify`` (the
  caller may close the waker, and so its descriptor, next): a delivery checks ``closed`` and
  registers in ``_waking`` under the lock, so once ``closed`` is set only deliveries already
  registered can still wake the reader, and close waits for them (a wake-up takes microseconds).
"""
from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Any

from emos.ratelimit import RateLimitedLog

_CLOSE_WAIT_S = 2.0  # bounds a close behind a wake-up that hangs; a normal one takes microseconds


class ArrivalQueue:
    """A bounded queue of decoded messages with the reading interface of
    :class:`emos.transport.pubsub.Subscriber` (``take_raw``, ``latest_raw``, ``has_news``,
    ``take``, ``latest``)."""

    def __init__(self, topic: str, queue_size: int, notify: Callable[[], None] | None, warn: RateLimitedLog):
        self.topic = topic
        self.queue_size = max(int(queue_size), 1)
        self.dropped = 0  # taken off the full queue to make room
        self.closed = False
        self._queue: collections.deque[tuple[int, Any, str]] = collections.deque()
        self._lock = threading.Lock()
        self._waking: list[bool] = []  # one entry per delivery between its queueing and its wake-up call
        self._notify = notify
        self._warn = warn

    # -- delivering (any thread) ---------------------------------------------------------------
    def arrive(self, stamp_ns: int, msg: Any, publisher: str) -> None:
        """Queue one decoded message and wake the node. Raises nothing: a delivering thread that
        died here would leave the subscriber looking alive while deaf."""
        waking = self._waking
        with self._lock:
            if self.closed:
                return
            queue = self._queue
            if len(queue) >= self.queue_size:
                queue.popleft()
                self.dropped += 1
            queue.append((stamp_ns, msg, publisher))
            waking.append(True)  # see close_arrivals(): we may wake the reader until we pop this
        try:
            if self._notify is not None:
                self._notify()
        except Exception as exc:  # noqa: BLE001
            self._warn.warning(f"notify:{self.topic}", "topic %s: waking the reader failed: %s", self.topic, exc)
        finally:
            waking.pop()

    def close_arrivals(self) -> bool:
        """Stop delivering, drop what is queued and wait for wake-ups in flight. ``False`` when it
        was closed already."""
        with self._lock:
            if self.closed:
                return False
            self.closed = True
            self._queue.clear()
        deadline = time.monotonic() + _CLOSE_WAIT_S
        while self._waking and time.monotonic() < deadline:
            time.sleep(0.0005)
        return True

    # -- reading (the node's thread) -----------------------------------------------------------
    def take_raw(self) -> list[tuple[int, Any, str]]:
        """Every queued ``(stamp_ns, message, publisher)``, oldest first."""
        if not self._queue:
            return []
        with self._lock:
            out = list(self._queue)
            self._queue.clear()
        return out

    def latest_raw(self) -> tuple[int, Any, str] | None:
        """The newest queued item (older ones are discarded), or ``None``."""
        with self._lock:
            if not self._queue:
                return None
            item = self._queue[-1]
            self._queue.clear()
        return item

    def has_news(self) -> bool:
        return bool(self._queue)

    def take(self) -> list[Any]:
        """Every queued message, oldest first."""
        return [msg for _, msg, _ in self.take_raw()]

    def latest(self) -> Any | None:
        """The newest queued message (older ones are discarded), or ``None``."""
        item = self.latest_raw()
        return None if item is None else item[1]

