"""``emos play FILE.mcap [--rate R] [--loop] [--topics ...]``: publish a recording into a running system.

A recording is untrusted input. What it may cost is bounded (``--max-chunk-mb`` per chunk,
``--max-topics`` rings, each sized to the largest message its channel carries in the chunk where
the channel first plays, not to a fixed size); damaged chunks are skipped and reported, never
played; topics EMOS cannot carry are skipped by name; SIGINT/SIGTERM end the play promptly, also
while a chunk is being read. The checks themselves live in :mod:`emos.interop.mcap_bag`.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
from pathlib import Path
from typing import Any, Callable

from emos.supervisor.cli_common import add_run_argument, join_run
from emos.supervisor.cli_record import add_import_argument, check_distribution, import_modules, stop_flag

log = logging.getLogger("emos.interop")

MiB = 1 << 20


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("file", help="an MCAP file (from `emos record`, or a ROS 2 bag in MCAP with shared types)")
    parser.add_argument("--rate", "-r", type=float, default=1.0, help="time scale: 2 plays twice as fast (default 1)")
    parser.add_argument("--loop", "-l", action="store_true", help="start over at the end, until Ctrl-C")
    parser.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="play only these topics (wildcards allowed)")
    parser.add_argument("--distribution", default="humble", help="ROS 2 distribution of the cdr channels' type definitions (default humble)")
    parser.add_argument("--max-chunk-mb", type=int, default=256, metavar="MB",
                        help="largest decompressed chunk to read, in MiB (default 256); a larger chunk is skipped and reported")
    parser.add_argument("--max-topics", type=int, default=256, metavar="N",
                        help="most topics to publish, one shared-memory ring each (default 256); a file with more is refused")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    add_import_argument(parser)


def _ring_capacity(largest: int) -> int:
    """Slot size of a topic's ring: its largest recorded message, plus room for the difference
    between a ROS 2 (cdr) message and the same message in EMOS's frame (a few dozen bytes)."""
    return largest + largest // 16 + 256


def _player_class() -> type:
    """The Player with `emos play`'s bounds (built lazily: importing record pulls in the transport)."""
    from emos.interop.record import Player
    from emos.msgs.registry import canonical_name
    from emos.transport.pubsub import Publisher, list_topics

    class SizedPublisher(Publisher):
        """A Publisher whose first ring holds ``capacity``-byte messages instead of the default
        64 KiB (x 18 slots: 1.1 MiB per topic whatever the data); it grows as any publisher does."""

        def __init__(self, ctx: Any, topic: str, msg_cls: type, capacity: int):
            self._first_capacity: int | None = capacity
            super().__init__(ctx, topic, msg_cls)
            self._first_capacity = None  # also when an existing ring was re-opened: growth sizes the next ones

        def _create_ring(self, generation: int, depth: int, capacity: int, *rest: Any) -> Any:
            if self._first_capacity is not None:
                capacity, self._first_capacity = self._first_capacity, None
            return super()._create_ring(generation, depth, capacity, *rest)

    class BoundedPlayer(Player):
        """Reads under ``limits`` (and the stop flag, while reading), creates a topic's ring only
        when its first message is played, sized to the data, and at most ``limits.max_topics``."""

        def __init__(self, *args: Any, limits: Any, **kw: Any):
            super().__init__(*args, **kw)
            self.limits = limits
            self.over_limit: set[str] = set()

        def topics_to_play(self, channels: dict) -> set[str]:
            return {ch.topic for ch in channels.values() if ch.cls is not None and self._wanted(ch.topic)}

        def _play_once(self, should_stop: Callable[[], bool], *rest: Any) -> Any:
            self.info.limits, self.info.should_stop = self.limits, should_stop
            return super()._play_once(should_stop, *rest)

        def _publisher(self, ch: Any) -> Any:
            if ch.cls is None:
                # Never the publisher of another channel of the same topic: its messages do not decode.
                if ch.topic not in self.skipped:
                    self.skipped[ch.topic] = ch.problem
                    log.warning("not playing %s: %s", _shown(ch.topic), ch.problem)
                return None
            pub = self.publishers.get(ch.topic)
            if pub is not None or ch.topic in self.refused or ch.topic in self.over_limit:
                return pub
            if len(self.publishers) >= self.limits.max_topics:
                if not self.over_limit:
                    log.warning("not playing %s, nor any further topic: %d topics play already, the limit (--max-topics)",
                                _shown(ch.topic), self.limits.max_topics)
                self.over_limit.add(ch.topic)
                return None
            # Subscribers refuse a ring of another type than the topic's, so never create one.
            current = list_topics(self.ctx).get(ch.topic, {}).get("type", "?")
            if current not in ("?", canonical_name(ch.cls)):
                self.skipped[ch.topic] = f"the running system carries {current} on it, the recording {canonical_name(ch.cls)}"
                log.warning("not playing %s: %s", ch.topic, self.skipped[ch.topic])
                self.refused.add(ch.topic)
                return None
            try:
                pub = SizedPublisher(self.ctx, ch.topic, ch.cls, _ring_capacity(ch.largest))
            except OSError as exc:  # out of /dev/shm or file descriptors: this topic, not the play, fails
                self.skipped[ch.topic] = f"cannot create its ring ({exc})"
                log.warning("not playing %s: %s", ch.topic, self.skipped[ch.topic])
                self.refused.add(ch.topic)
                return None
            self.publishers[ch.topic] = pub
            return pub

    return BoundedPlayer


def _shown(topic: str, width: int = 60) -> str:
    """A topic name as printed: a hostile file's names can be any length or contain anything."""
    text = repr(topic) if not topic or not topic.isprintable() or " " in topic else topic
    return text if len(text) <= width else f"{text[:width - 20]}...({len(topic)} characters)"


def run(args: argparse.Namespace) -> int:
    from emos.interop.mcap_bag import BagInfo, NotMcapFile, ReadLimits, read_channels
    from emos.interop.record import default_progress
    from emos.transport.pubsub import TopicTypeError

    import_modules(args.imports)
    if not Path(args.file).is_file():
        raise SystemExit(f"emos play: no such file {args.file!r}")
    if not args.rate > 0:
        raise SystemExit(f"emos play: --rate must be > 0, got {args.rate}")
    check_distribution("emos play", args.distribution)
    if not 1 <= args.max_chunk_mb <= 64 * 1024:
        raise SystemExit(f"emos play: --max-chunk-mb must be 1..65536, got {args.max_chunk_mb}")
    if args.max_topics < 1:
        raise SystemExit(f"emos play: --max-topics must be >= 1, got {args.max_topics}")
    limits = ReadLimits(max_chunk_bytes=args.max_chunk_mb * MiB, max_topics=args.max_topics)
    try:
        channels = read_channels(args.file, BagInfo(limits=limits), args.distribution)
    except NotMcapFile as exc:
        raise SystemExit(f"emos play: {exc}") from exc
    ctx = join_run(args.run)
    player = _player_class()(ctx, args.file, rate=args.rate, loop=args.loop, topics=args.topics,
                             distribution=args.distribution, limits=limits)
    # A file whose summary lists more topics than allowed is refused before any ring exists;
    # one without a summary finds out as it plays (BoundedPlayer skips the topics past the limit).
    n_topics = len(player.topics_to_play(channels))
    if n_topics > limits.max_topics:
        raise SystemExit(f"emos play: {args.file} has {n_topics} topics to play, more than --max-topics {limits.max_topics} "
                         "allows (each is a shared-memory ring): raise --max-topics, or pick topics with --topics")
    stop = stop_flag()
    try:
        total = player.run(lambda: bool(stop), None if args.quiet else default_progress())
    except TopicTypeError as exc:
        raise SystemExit(f"emos play: {exc}") from exc
    finally:
        player.close()
    if not args.quiet:
        sys.stderr.write("\n")
    info = player.info
    stopped = f"; stopped by {signal.Signals(stop[0]).name}" if stop else ""
    print(f"played {total} messages from {args.file}"
          + (" (the file was cut short: played up to its last complete chunk)" if info.truncated else "")
          + ("; the system stopped" if player.run_ended else "") + stopped)
    for topic, n in sorted(player.published.items()):
        print(f"  {topic:<40} {n:7d} messages")
    for topic, n in sorted(player.errors.items()):
        print(f"  {topic:<40} {n} damaged messages not played (see the log)")
    for topic, why in sorted(player.skipped.items()):
        print(f"  {_shown(topic):<40} skipped: {why}")
    if player.over_limit:
        print(f"  {len(player.over_limit)} topics not played: over the limit of {limits.max_topics} topics (--max-topics)")
    if info.damaged:
        n, lost = len(info.damaged), info.lost
        uncounted = sum(d.lost is None for d in info.damaged)
        if not uncounted:
            what = f"{lost} messages in them not played"
        elif uncounted == n:
            what = "their messages not played (the file has no message index to count them)"
        else:
            what = f"{lost} messages in them not played, and those of {uncounted} the file has no message index for"
        print(f"  {n} damaged chunk{'s' if n != 1 else ''} skipped, {what} (see the log)")
    for problem in info.problems:
        print(f"  file: {problem}")
    return 0
