"""Recording a running system's topics into MCAP, and playing recordings back into one.

:class:`Recorder` is a subscriber like any other (it joins the run from outside through its run
directory), so components see no difference between a run being recorded or not, beyond the
recorder's CPU use. :class:`Player` publishes recorded messages with their original spacing, so a
recipe runs on recorded data with no sensors or simulator.
"""
from __future__ import annotations

import errno
import fnmatch
import io
import logging
import os
import stat
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from attrs import define

from emos.interop.mcap_bag import PROFILE, BagWriter
from emos.interop.mcap_read import BagChannel, BagInfo, ReadLimits, read_bag
from emos.interop.ros2_cdr import DEFAULT_DISTRIBUTION, CdrError
from emos.interop.tap import RunWatch, TopicTap, normalize_patterns
from emos.msgs.codec import DecodeError
from emos.msgs.registry import canonical_name
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, list_topics

log = logging.getLogger("emos.interop")
# Errors that repeat with every message: the first at once, then one counted line per topic per 10 s.
_limited = RateLimitedLog(log, interval=10.0)

Progress = Callable[[str], None]


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


DEFAULT_DEFER_S = 0.005


def describe_os_error(exc: OSError) -> str:
    """``No space left on device (ENOSPC)``: the OS error without Python's ``[Errno 28]`` noise."""
    name = errno.errorcode.get(exc.errno or 0)
    text = exc.strerror or str(exc)
    return f"{text} ({name})" if name else text


@define
class WriteFailure:
    """The recording stopped because its file could not be written."""

    path: Path
    error: OSError
    kept: int | None        # size of the valid MCAP file left behind; None: it could not be closed properly
    problem: str = ""       # why it could not (when ``kept`` is None)

    def message(self) -> str:
        head = f"writing {self.path} failed: {describe_os_error(self.error)}; recording stopped"
        if self.kept is not None:
            size = _mb(self.kept) if self.kept >= 1e6 else f"{self.kept / 1e3:.1f} kB"
            return (f"{head}; {self.path} is a valid MCAP file ({size}) holding the chunks written before the error "
                    "(the messages of the chunk being written are lost)")
        return f"{head}; {self.problem}"


def _closing_records() -> bytes:
    """Data End and a Footer without summary, then the magic: what ends a valid MCAP file."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC

    rb = RecordBuilder()
    DataEnd(data_section_crc=0).write(rb)  # 0: "not computed", as the specification allows
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(rb)
    records: bytes = rb.end()
    return records + MCAP0_MAGIC


def _empty_mcap() -> bytes:
    from mcap.writer import Writer

    buf = io.BytesIO()
    writer = Writer(buf)
    writer.start(profile=PROFILE, library="emos")
    writer.finish()
    return buf.getvalue()


def salvage(path: Path, good: int, error: OSError) -> WriteFailure:
    """After a failed write: cut the file back to ``good`` (the end of its last complete chunk,
    all of which reached the OS) and end it there as a valid MCAP file. If even that fails, the
    file is left cut at ``good``: readable up to its last complete chunk, as after a SIGKILL."""
    try:
        fd = os.open(path, os.O_WRONLY)
    except OSError as exc:
        return WriteFailure(path, error, None, f"it could not be reopened to close it properly ({describe_os_error(exc)})")
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return WriteFailure(path, error, None, "it is not a regular file, so nothing recorded could be kept")
        # good == 0: not even the header reached the OS; an empty recording then.
        tail = _empty_mcap() if good == 0 else _closing_records()
        start = good
        try:
            os.ftruncate(fd, start)
            view = memoryview(tail)
            while view:
                n = os.pwrite(fd, view, start)
                view, start = view[n:], start + n
            os.fsync(fd)
        except OSError as exc:
            try:
                os.ftruncate(fd, good)
            except OSError:
                pass
            left = ("it is left empty" if good == 0 else
                    "it is readable up to its last complete chunk (emos play says it was cut short)")
            return WriteFailure(path, error, None,
                                f"the device refused even the few bytes that end the file properly ({describe_os_error(exc)}): {left}")
        return WriteFailure(path, error, start)
    finally:
        os.close(fd)


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
        self.write_error: OSError | None = None  # the file could not be written: the recording stops
        self.failure: WriteFailure | None = None  # set by close() after a write error

    def run(self, should_stop: Callable[[], bool], duration: float | None = None, progress: Progress | None = None,
            progress_every: float = 1.0) -> None:
        """Record until ``should_stop()``, ``duration`` seconds or a write error (:attr:`write_error`);
        the file stays open (see :meth:`close`)."""
        start = time.monotonic()
        next_report = start + progress_every
        for topic in self.tap.subs:
            log.info("recording %s (%s)", topic, self.tap.types[topic].__name__)
        try:
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
        except OSError as exc:
            # Only the file's errors end a recording quietly as a write failure; anything else
            # is a fault of ours and is raised as it is, not reported as the disk's.
            if exc is not self.write_error:
                raise

    def step(self) -> int:
        """Write every message that arrived since the last call; returns how many. Raises the
        OSError of a failed write (full disk, I/O error), kept in :attr:`write_error`: the
        recording cannot go on."""
        items = self.tap.take()
        now = time.time_ns()
        for topic, stamp, frame in items:
            try:
                self.writer.write_frame(topic, self.tap.types[topic], frame, stamp, now)
            except OSError as exc:
                self.write_error = exc
                raise
            except Exception as exc:  # one undecodable message must not end the recording
                n = self.errors[topic] = self.errors.get(topic, 0) + 1
                _limited.error(f"record:{topic}", "topic %s: message not recorded (%d so far): %s", topic, n, exc)
        return len(items)

    def report(self, elapsed: float) -> str:
        parts = [f"{topic} {st.messages}" for topic, st in sorted(self.writer.stats.items())]
        dropped = self.tap.dropped()
        tail = f"  dropped {dropped}" if dropped else ""
        return f"recording {elapsed:6.1f} s  {_mb(self.writer.size):>9}  " + "  ".join(parts) + tail

    def close(self) -> None:
        """Close the file (summary written); after a write error, see :attr:`failure`."""
        try:
            self.tap.close()
        finally:
            self._close_writer()

    def _close_writer(self) -> None:
        if self.writer.closed:
            return
        good = self.writer.size  # the end of the last chunk that reached the OS
        if self.write_error is None:
            try:
                self.writer.close()
                return
            except OSError as exc:  # the summary did not fit, or the data never reached the disk
                self.write_error = exc
        else:
            try:
                self.writer.close()  # releases the file; whatever it writes past `good` is cut off below
            except Exception as exc:
                log.debug("closing %s after a write error: %s", self.writer.path, exc)
        self.failure = salvage(self.writer.path, good, self.write_error)


class Player:
    """Publishes a recording's messages into a run, spaced as they were published.

    ``rate`` scales time (2.0 plays twice as fast); ``loop`` starts over at the end; ``topics``
    (names or wildcards) limits what is played. Channels we cannot decode are reported and skipped.
    """

    def __init__(self, ctx: RunContext, path: str, rate: float = 1.0, loop: bool = False, topics: Iterable[str] | None = None,
                 distribution: str = DEFAULT_DISTRIBUTION, limits: ReadLimits | None = None):
        """``limits``: what a (possibly hostile) file may cost to read, and how many topics play."""
        if not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate!r}")
        self.limits = limits if limits is not None else ReadLimits()
        self.over_limit: set[str] = set()  # topics not played: --max-topics were playing already
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
        self.info = BagInfo(limits=self.limits)
        self.alive = RunWatch(ctx)
        self.run_ended = False  # the system stopped while we played

    def _wanted(self, topic: str) -> bool:
        return not self.patterns or any(fnmatch.fnmatchcase(topic, p) for p in self.patterns)

    def topics_to_play(self, channels: dict[int, BagChannel]) -> set[str]:
        """The topics of ``channels`` (a file's summary) that this player would publish."""
        return {ch.topic for ch in channels.values() if ch.cls is not None and self._wanted(ch.topic)}

    def _skip(self, topic: str, reason: str) -> None:
        self.skipped[topic] = reason
        log.warning("not playing %s: %s", shown_topic(topic), reason)

    def _publisher(self, ch: BagChannel) -> Publisher | None:
        """The publisher of ``ch``'s topic, created when its first message plays; None if the
        channel is not to be played."""
        if ch.cls is None:
            # Never the publisher of another channel of the same topic: its messages do not decode.
            if ch.topic not in self.skipped:
                self._skip(ch.topic, ch.problem)
            return None
        pub = self.publishers.get(ch.topic)
        if pub is not None or ch.topic in self.refused or ch.topic in self.over_limit:
            return pub
        if len(self.publishers) >= self.limits.max_topics:
            if not self.over_limit:
                log.warning("not playing %s, nor any further topic: %d topics play already, the limit (--max-topics)",
                            shown_topic(ch.topic), self.limits.max_topics)
            self.over_limit.add(ch.topic)
            return None
        # Subscribers refuse a ring of another type than the topic's, so never create one.
        current = list_topics(self.ctx).get(ch.topic, {}).get("type", "?")
        if current not in ("?", canonical_name(ch.cls)):
            self._skip(ch.topic, f"the running system carries {current} on it, the recording {canonical_name(ch.cls)}")
            self.refused.add(ch.topic)
            return None
        try:
            # Sized to the data (small messages get a ring of a few KiB, not 64 KiB x 18 slots).
            pub = Publisher(self.ctx, ch.topic, ch.cls, capacity=ring_capacity(ch.largest))
        except OSError as exc:  # out of /dev/shm or file descriptors: this topic, not the play, fails
            self._skip(ch.topic, f"cannot create its ring ({exc})")
            self.refused.add(ch.topic)
            return None
        self.publishers[ch.topic] = pub
        return pub

    def run(self, should_stop: Callable[[], bool], progress: Progress | None = None, progress_every: float = 1.0) -> int:
        """Play (and replay with ``loop``) until done or ``should_stop()``; returns messages published."""
        total = 0
        while True:
            self.info = BagInfo(limits=self.limits)
            self.info.should_stop = should_stop  # honoured while a chunk is read, too
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
                _limited.error(f"play:{m.topic}", "topic %s: message not played (%d so far): %s", m.topic, n, exc)
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


def ring_capacity(largest: int) -> int:
    """Slot size of a played topic's ring: its largest recorded message, plus room for the
    difference between a ROS 2 (cdr) message and the same message in EMOS's frame."""
    return max(1024, largest + largest // 16 + 256)


def shown_topic(topic: str, width: int = 60) -> str:
    """A topic name as printed: a hostile file's names can be any length or contain anything."""
    text = repr(topic) if not topic or not topic.isprintable() or " " in topic else topic
    return text if len(text) <= width else f"{text[:width - 20]}...({len(topic)} characters)"
