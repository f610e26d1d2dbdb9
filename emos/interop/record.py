"""Recording a running system's topics into MCAP, and playing recordings back into one.

:class:`Recorder` is a subscriber like any other (it joins the run from outside through its run
directory), so components see no difference between a run being recorded or not, beyond the
recorder's CPU use. :class:`Player` publishes recorded messages with their original spacing, so a
recipe runs on recorded data with no sensors or simulator.
"""
from __future__ import annotations

import fnmatch
import logging
import time
from typing import Any, Callable, Iterable

from emos.interop.mcap_bag import BagChannel, BagInfo, BagWriter, read_bag
from emos.interop.ros2_cdr import DEFAULT_DISTRIBUTION, CdrError
from emos.interop.tap import RunWatch, TopicTap, normalize_patterns
from emos.transport.context import RunContext
from emos.msgs.codec import DecodeError
from emos.msgs.registry import canonical_name
from emos.transport.pubsub import Publisher, list_topics

log = logging.getLogger("emos.interop")

Progress = Callable[[str], None]


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


DEFAULT_DEFER_S = 0.005


class Recorder:
    """Writes the wanted topics of a run (all by default, new ones included) to one MCAP file.

    ``defer``: seconds the recorder waits after a wake-up before it reads. The subscribers that
    the same message woke (the robot's own components) then get the CPU first, instead of
    waiting behind the recorder's copying: on a 2-core machine this halves the camera's p90
    latency to its other subscribers while recording (docs/benchmarks.md). It must stay well
    below the time a topic's queue lasts (depth / rate: 330 ms for a 10-deep camera queue at
    30 Hz, 10 ms for a 10-deep 1 kHz topic); losses are counted and reported.
    """

    def __init__(self, ctx: RunContext, path: str, topics: Iterable[str] | None = None, exclude: Iterable[str] | None = None,
                 compression: str = "none", chunk_size: int = 1 << 20, distribution: str = DEFAULT_DISTRIBUTION,
                 defer: float = DEFAULT_DEFER_S):
        if not 0 <= defer <= 1.0:
            raise ValueError(f"defer must be 0..1 s, got {defer!r}")
        self.defer = defer
        self.writer = BagWriter(path, compression=compression, chunk_size=chunk_size, distribution=distribution,
                                metadata={"run_id": ctx.run_id})
        try:
            self.tap = TopicTap(ctx, topics, exclude)
        except BaseException:
            self.writer.close()
            raise
        self.errors: dict[str, int] = {}
        self.alive = RunWatch(ctx)
        self.run_ended = False  # the system stopped while we recorded

    def run(self, should_stop: Callable[[], bool], duration: float | None = None, progress: Progress | None = None,
            progress_every: float = 1.0) -> None:
        """Record until ``should_stop()`` or ``duration`` seconds; the file stays open (see :meth:`close`)."""
        start = time.monotonic()
        next_report = start + progress_every
        for topic in self.tap.subs:
            log.info("recording %s (%s)", topic, self.tap.types[topic].__name__)
        while not should_stop() and (duration is None or time.monotonic() - start < duration):
            if not self.alive():
                self.run_ended = True
                break
            self.tap.wait(0.1)
            if self.defer:
                time.sleep(self.defer)
            self.step()
            for topic in self.tap.discover():
                log.info("recording %s (%s), which appeared during the recording", topic, self.tap.types[topic].__name__)
            now = time.monotonic()
            if progress is not None and now >= next_report:
                next_report = now + progress_every
                progress(self.report(now - start))
        self.step()

    def step(self) -> int:
        """Write every message that arrived since the last call; returns how many."""
        items = self.tap.take()
        now = time.time_ns()
        for topic, stamp, frame in items:
            try:
                self.writer.write_frame(topic, self.tap.types[topic], frame, stamp, now)
            except Exception as exc:  # one undecodable message must not end the recording
                n = self.errors[topic] = self.errors.get(topic, 0) + 1
                if n == 1 or n % 100 == 0:
                    log.error("topic %s: message not recorded (%d so far): %s", topic, n, exc)
        return len(items)

    def report(self, elapsed: float) -> str:
        parts = [f"{topic} {st.messages}" for topic, st in sorted(self.writer.stats.items())]
        dropped = self.tap.dropped()
        tail = f"  dropped {dropped}" if dropped else ""
        return f"recording {elapsed:6.1f} s  {_mb(self.writer.size):>9}  " + "  ".join(parts) + tail

    def close(self) -> None:
        try:
            self.tap.close()
        finally:
            self.writer.close()


class Player:
    """Publishes a recording's messages into a run, spaced as they were published.

    ``rate`` scales time (2.0 plays twice as fast); ``loop`` starts over at the end; ``topics``
    (names or wildcards) limits what is played. Channels we cannot decode are reported and skipped.
    """

    def __init__(self, ctx: RunContext, path: str, rate: float = 1.0, loop: bool = False, topics: Iterable[str] | None = None,
                 distribution: str = DEFAULT_DISTRIBUTION):
        if not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate!r}")
        self.ctx = ctx
        self.path = path
        self.rate = float(rate)
        self.loop = loop
        self.patterns = normalize_patterns(topics)
        self.distribution = distribution
        self.publishers: dict[str, Publisher] = {}
        self.published: dict[str, int] = {}
        self.skipped: dict[str, str] = {}
        self.refused: set[str] = set()
        self.errors: dict[str, int] = {}
        self.info = BagInfo()
        self.alive = RunWatch(ctx)
        self.run_ended = False  # the system stopped while we played

    def _wanted(self, topic: str) -> bool:
        return not self.patterns or any(fnmatch.fnmatchcase(topic, p) for p in self.patterns)

    def _publisher(self, ch: BagChannel) -> Publisher | None:
        pub = self.publishers.get(ch.topic)
        if pub is None:
            if ch.topic in self.refused:
                return None
            if ch.cls is None:
                if ch.topic not in self.skipped:
                    self.skipped[ch.topic] = ch.problem
                    log.warning("not playing %s: %s", ch.topic, ch.problem)
                return None
            # Subscribers refuse a ring of another type than the topic's, so never create one.
            current = list_topics(self.ctx).get(ch.topic, {}).get("type", "?")
            if current not in ("?", canonical_name(ch.cls)):
                self.skipped[ch.topic] = f"the running system carries {current} on it, the recording {canonical_name(ch.cls)}"
                log.warning("not playing %s: %s", ch.topic, self.skipped[ch.topic])
                self.refused.add(ch.topic)
                return None
            pub = self.publishers[ch.topic] = Publisher(self.ctx, ch.topic, ch.cls)
        return pub

    def run(self, should_stop: Callable[[], bool], progress: Progress | None = None, progress_every: float = 1.0) -> int:
        """Play (and replay with ``loop``) until done or ``should_stop()``; returns messages published."""
        total = 0
        while True:
            self.info = BagInfo()
            n, stopped = self._play_once(should_stop, progress, progress_every)
            total += n
            if stopped or not self.loop or n == 0:
                return total

    def _play_once(self, should_stop: Callable[[], bool], progress: Progress | None, progress_every: float) -> tuple[int, bool]:
        t0_bag: int | None = None
        t0_wall = 0.0
        played = 0
        next_report = time.monotonic() + progress_every
        for m in read_bag(self.path, info=self.info, distribution=self.distribution):
            if not self._wanted(m.topic):
                continue
            pub = self._publisher(m.channel)
            if pub is None:
                continue
            try:
                msg = m.decode(self.distribution)
            except (CdrError, DecodeError) as exc:  # a damaged message: skip it, keep playing
                n = self.errors[m.topic] = self.errors.get(m.topic, 0) + 1
                if n == 1 or n % 100 == 0:
                    log.error("topic %s: message not played (%d so far): %s", m.topic, n, exc)
                continue
            if t0_bag is None:
                t0_bag, t0_wall = m.publish_ns, time.monotonic()
            target = t0_wall + (m.publish_ns - t0_bag) / 1e9 / self.rate
            while True:  # sleep in slices so Ctrl-C is honoured during long gaps
                if should_stop():
                    return played, True
                if not self.alive():
                    self.run_ended = True
                    return played, True
                delay = target - time.monotonic()
                if delay <= 0:
                    break
                time.sleep(min(delay, 0.1))
            pub.publish(msg)
            played += 1
            self.published[m.topic] = self.published.get(m.topic, 0) + 1
            now = time.monotonic()
            if progress is not None and now >= next_report:
                next_report = now + progress_every
                progress(self.report(now - t0_wall, (m.publish_ns - t0_bag) / 1e9))
        return played, False

    def report(self, elapsed: float, bag_time: float) -> str:
        parts = [f"{topic} {n}" for topic, n in sorted(self.published.items())]
        return f"playing {elapsed:6.1f} s (recording time {bag_time:6.1f} s)  " + "  ".join(parts)

    def close(self, linger: float = 0.5) -> None:
        """Close the publishers, after ``linger`` seconds in which subscribers read the last messages."""
        if self.publishers and linger > 0:
            time.sleep(linger)
        for pub in self.publishers.values():
            pub.close()
        self.publishers.clear()


def default_progress(stream: Any = None) -> Progress:
    """One line per report; rewritten in place on a terminal."""
    import sys

    out = stream or sys.stderr
    tty = out.isatty()

    def show(line: str) -> None:
        out.write(("\r\x1b[K" + line) if tty else line + "\n")
        out.flush()

    return show
