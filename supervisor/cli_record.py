"""``emos record [TOPICS...] -o FILE.mcap``: record a running system's topics into MCAP."""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from pathlib import Path

from emos.supervisor.cli_common import add_run_argument, join_run


def add_import_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE",
                        help="import this Python module first, to register message types a recipe defines (repeatable)")


def import_modules(names: list[str]) -> None:
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            raise SystemExit(f"emos: cannot import {name!r} (from --import): {exc}") from exc


def check_distribution(command: str, name: str) -> None:
    from emos.interop.ros2_cdr import DISTRIBUTIONS

    if name not in DISTRIBUTIONS:
        raise SystemExit(f"{command}: --distribution must be one of {', '.join(DISTRIBUTIONS)}, got {name!r}")


def stop_flag() -> list[int]:
    """A list that gets the signal number when SIGINT or SIGTERM arrives (the loops poll it)."""
    got: list[int] = []

    def handler(signum: int, frame: object) -> None:
        got.append(signum)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return got


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("topics", nargs="*", help="topics to record, shell wildcards allowed (default: all, new ones included)")
    parser.add_argument("-o", "--output", required=True, help="the MCAP file to write")
    parser.add_argument("-x", "--exclude", action="append", default=[], metavar="TOPIC", help="topic (or wildcard) not to record")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: until Ctrl-C or SIGTERM)")
    parser.add_argument("--compression", choices=("none", "zstd", "lz4"), default="none",
                        help="chunk compression (default none, as rosbag2: the least CPU; zstd halves camera images for ~1 ms of CPU per 640x480 frame)")
    parser.add_argument("--chunk-size", type=int, default=1 << 20, help="bytes per chunk (default 1 MiB); a killed recorder loses at most one")
    parser.add_argument("--distribution", default="humble", help="ROS 2 distribution of the cdr channels' type definitions (default humble)")
    parser.add_argument("--nice", type=int, default=0, help="lower the recorder's CPU priority by this much (0-19), so that it yields to the robot's own processes")
    parser.add_argument("--defer-ms", type=float, default=5.0,
                        help="wait this long after a wake-up before reading, so the robot's own subscribers of the same message "
                             "run first (default 5; keep it well below a topic's queue duration; 0 reads at once)")
    parser.add_argument("--idle", action="store_true",
                        help="run the recorder under SCHED_IDLE: any other process that wants the CPU goes first "
                             "(least disturbance; on a saturated CPU the recorder may fall behind and lose messages, which it reports)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    add_import_argument(parser)


def run(args: argparse.Namespace) -> int:
    from emos.interop.record import Recorder, default_progress

    import_modules(args.imports)
    out = Path(args.output)
    if out.exists() and not args.force:
        raise SystemExit(f"emos record: {out} exists (use --force to overwrite)")
    if args.duration is not None and args.duration <= 0:
        raise SystemExit(f"emos record: --duration must be > 0 seconds, got {args.duration}")
    if not 0 <= args.defer_ms <= 1000:
        raise SystemExit(f"emos record: --defer-ms must be 0..1000, got {args.defer_ms}")
    if not 0 <= args.nice <= 19:
        raise SystemExit(f"emos record: --nice must be 0..19, got {args.nice}")
    if args.nice:
        os.nice(args.nice)
    if args.idle:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    check_distribution("emos record", args.distribution)
    ctx = join_run(args.run)
    stop = stop_flag()
    recorder = Recorder(ctx, str(out), args.topics, args.exclude, compression=args.compression,
                        chunk_size=args.chunk_size, distribution=args.distribution, defer=args.defer_ms / 1000.0)
    try:
        recorder.run(lambda: bool(stop), args.duration, None if args.quiet else default_progress())
    finally:
        recorder.close()
    stats = recorder.writer.stats
    if not args.quiet:
        sys.stderr.write("\n")
    print(f"recorded {sum(s.messages for s in stats.values())} messages on {len(stats)} topics into {out} "
          f"({out.stat().st_size / 1e6:.1f} MB)" + (f"; stopped by {signal.Signals(stop[0]).name}" if stop else "")
          + ("; the system stopped" if recorder.run_ended else ""))
    dropped = recorder.tap.dropped_total
    for topic, st in sorted(stats.items()):
        lost = dropped.get(topic, 0)
        print(f"  {topic:<40} {st.messages:7d} messages  {st.bytes / 1e6:9.1f} MB"
              + (f"  LOST {lost} (the recorder fell behind the publisher's queue)" if lost else ""))
    for topic, n in sorted(recorder.errors.items()):
        print(f"  {topic:<40} {n} messages could not be recorded (see the log)")
    return 0
