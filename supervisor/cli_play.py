"""``emos play FILE.mcap [--rate R] [--loop] [--topics ...]``: publish a recording into a running system."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from emos.supervisor.cli_common import add_run_argument, join_run
from emos.supervisor.cli_record import add_import_argument, check_distribution, import_modules, stop_flag


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("file", help="an MCAP file (from `emos record`, or a ROS 2 bag in MCAP with shared types)")
    parser.add_argument("--rate", "-r", type=float, default=1.0, help="time scale: 2 plays twice as fast (default 1)")
    parser.add_argument("--loop", "-l", action="store_true", help="start over at the end, until Ctrl-C")
    parser.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="play only these topics (wildcards allowed)")
    parser.add_argument("--distribution", default="humble", help="ROS 2 distribution of the cdr channels' type definitions (default humble)")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    add_import_argument(parser)


def run(args: argparse.Namespace) -> int:
    from emos.interop.record import Player, default_progress
    from emos.transport.pubsub import TopicTypeError

    import_modules(args.imports)
    if not Path(args.file).is_file():
        raise SystemExit(f"emos play: no such file {args.file!r}")
    if not args.rate > 0:
        raise SystemExit(f"emos play: --rate must be > 0, got {args.rate}")
    check_distribution("emos play", args.distribution)
    ctx = join_run(args.run)
    stop = stop_flag()
    player = Player(ctx, args.file, rate=args.rate, loop=args.loop, topics=args.topics, distribution=args.distribution)
    try:
        total = player.run(lambda: bool(stop), None if args.quiet else default_progress())
    except TopicTypeError as exc:
        raise SystemExit(f"emos play: {exc}") from exc
    finally:
        player.close()
    if not args.quiet:
        sys.stderr.write("\n")
    print(f"played {total} messages from {args.file}"
          + (" (the file was cut short: played up to its last complete chunk)" if player.info.truncated else "")
          + ("; the system stopped" if player.run_ended else ""))
    for topic, n in sorted(player.published.items()):
        print(f"  {topic:<40} {n:7d} messages")
    for topic, n in sorted(player.errors.items()):
        print(f"  {topic:<40} {n} damaged messages not played (see the log)")
    for topic, why in sorted(player.skipped.items()):
        print(f"  {topic:<40} skipped: {why}")
    return 0
