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

from emos.tools.cli.common import add_run_argument, join_run
from emos.tools.cli.record import add_import_argument, check_distribution, import_modules, stop_flag

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


def run(args: argparse.Namespace) -> int:
    from emos.interop.mcap_read import BagInfo, NotMcapFile, ReadLimits, read_channels
    from emos.interop.record import Player, default_progress, shown_topic
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
    player = Player(ctx, args.file, rate=args.rate, loop=args.loop, topics=args.topics,
                    distribution=args.distribution, limits=limits)
    # A file whose summary lists more topics than allowed is refused before any ring exists;
    # one without a summary finds out as it plays (the player skips the topics past the limit).
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
        print(f"  {shown_topic(topic):<40} skipped: {why}")
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
