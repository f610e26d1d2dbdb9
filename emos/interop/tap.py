"""Following the topics of a running system from outside it: the recorder's and the bridges' input.

A :class:`TopicTap` subscribes to the topics it is asked for (all of them by default) through
the ordinary :class:`~emos.transport.pubsub.Subscriber`, keeps looking for topics that appear
later, and hands out raw frames with their publish stamps, so a recorder can store them without
decoding what it does not need to.
"""
from __future__ import annotations

import fnmatch
import logging
import os
import select
import time
from collections.abc import Iterable
from typing import Any

from emos.msgs.registry import UnknownMessageType, resolve
from emos.ratelimit import RateLimitedLog
from emos.transport.context import SHM_DIR, RunContext, run_is_alive
from emos.transport.pubsub import Subscriber, TopicTypeError, list_topics
from emos.transport.waker import Waker

log = logging.getLogger("emos.interop")
# Errors that repeat with every message: the first at once, then one counted line per topic per 10 s.
_limited = RateLimitedLog(log, interval=10.0)

_MTIME_SLACK_NS = 50_000_000  # well above any kernel's timestamp tick


def normalize_patterns(topics: Iterable[str] | None) -> list[str]:
    """``scan`` -> ``/scan``; shell wildcards (``/camera/*``) are kept."""
    return [t if t.startswith("/") else "/" + t for t in (topics or [])]


class RunWatch:
    """Whether the run we joined from outside still exists (checked at most once per ``every`` s)."""

    def __init__(self, ctx: RunContext, every: float = 1.0):
        self.ctx, self.every = ctx, every
        self._next = 0.0
        self._alive = True

    def __call__(self) -> bool:
        now = time.monotonic()
        if self._alive and now >= self._next:
            self._next = now + self.every
            self._alive = self.ctx.run_dir.exists() and run_is_alive(self.ctx.run_id)
        return self._alive


class TopicTap:
    """Subscriptions to a run's topics, found by name (with wildcards) or all of them.

    ``exclude`` patterns win over ``topics``. ``queue_size`` is how many messages per topic may
    pile up between two :meth:`take` calls before the oldest are dropped (and counted).
    """

    def __init__(self, ctx: RunContext, topics: Iterable[str] | None = None, exclude: Iterable[str] | None = None,
                 queue_size: int = 1000, use_waker: bool = True, discover_every: float = 0.5):
        self.ctx = ctx
        self.patterns = normalize_patterns(topics)
        self.exclude = normalize_patterns(exclude)
        self.queue_size = queue_size
        self.discover_every = discover_every
        self.waker = Waker(ctx, background=True) if use_waker else None  # an observer: woken after the robot's readers
        self.subs: dict[str, Subscriber] = {}
        self.types: dict[str, type] = {}
        self._refused: set[tuple[str, str]] = set()
        self.dropped_total: dict[str, int] = {}  # kept by close()
        self.errors: dict[str, int] = {}
        self._shm_mtime = -1
        self._scanned_at_ns = 0
        self._next_discovery = 0.0
        try:
            self.discover(force=True)
        except BaseException:
            self.close()
            raise

    def wanted(self, topic: str) -> bool:
        if any(fnmatch.fnmatchcase(topic, p) for p in self.exclude):
            return False
        return not self.patterns or any(fnmatch.fnmatchcase(topic, p) for p in self.patterns)

    def discover(self, force: bool = False) -> list[str]:
        """Subscribe to wanted topics that have a publisher now; returns the new ones."""
        now = time.monotonic()
        if not force and now < self._next_discovery:
            return []
        self._next_discovery = now + self.discover_every
        mtime = os.stat(SHM_DIR).st_mtime_ns
        # An unchanged mtime proves nothing new only if our last scan came clearly after it:
        # tmpfs timestamps are coarse, so a ring created in the tick of our scan leaves it as it was.
        if not force and mtime == self._shm_mtime and self._scanned_at_ns - mtime > _MTIME_SLACK_NS:
            return []
        self._shm_mtime = mtime
        self._scanned_at_ns = time.time_ns()
        new: list[str] = []
        for topic, info in list_topics(self.ctx).items():
            if topic in self.subs or not info["publishers"] or not self.wanted(topic):
                continue
            type_name = info["type"]
            try:
                cls = resolve(type_name)
                sub = Subscriber(self.ctx, topic, cls, waker=self.waker, queue_size=self.queue_size, loans=1)
            except (UnknownMessageType, TopicTypeError) as exc:
                if (topic, type_name) not in self._refused:
                    self._refused.add((topic, type_name))
                    log.warning("topic %s (%s) skipped: %s (register the type by importing its module, see --import)", topic, type_name, exc)
                continue
            except OSError as exc:
                if not self.ctx.run_dir.exists():
                    # The system is stopping: its run directory, where subscribers register, went
                    # away between the listing and now. Nothing more to follow.
                    return new
                n = self.errors[topic] = self.errors.get(topic, 0) + 1
                _limited.error(f"subscribe:{topic}", "topic %s: cannot subscribe (%d tries so far, tried again later): %s", topic, n, exc)
                continue
            self.subs[topic] = sub
            self.types[topic] = cls
            new.append(topic)
        return new

    def wait(self, timeout: float) -> None:
        """Sleep until a subscribed topic has news, or ``timeout`` seconds."""
        if self.waker is None:
            time.sleep(timeout)
            return
        select.select([self.waker.fd], [], [], timeout)
        self.waker.drain()

    def take(self) -> list[tuple[str, int, Any]]:
        """Every new message as ``(topic, publish stamp ns, raw frame)``, oldest first."""
        out: list[tuple[str, int, Any]] = []
        for topic, sub in self.subs.items():
            try:
                got = sub.take_raw()
            except TopicTypeError as exc:
                # A second publisher with another type on the topic: keep reading the first one's
                # messages, and say so (rate-limited: this repeats at every read).
                n = self.errors[topic] = self.errors.get(topic, 0) + 1
                _limited.error(f"type:{topic}", "topic %s: %s (%d times)", topic, exc, n)
                continue
            for stamp, frame, _pub in got:
                out.append((topic, stamp, frame))
        if len(self.subs) > 1:
            out.sort(key=lambda item: item[1])
        return out

    def dropped(self) -> dict[str, int]:
        return {t: s.dropped for t, s in self.subs.items() if s.dropped}

    def close(self) -> None:
        self.dropped_total = self.dropped()
        for sub in self.subs.values():
            sub.close()
        self.subs.clear()
        if self.waker is not None:
            self.waker.close()
            self.waker = None
