"""``emos record [TOPICS...] -o FILE.mcap``: record a running system's topics into MCAP."""
from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
from pathlib import Path

from emos.tools.cli.common import add_run_argument, join_run


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


MAX_CHUNK_SIZE = 256 << 20  # a chunk is built in memory, and a killed recorder loses the one it was filling


def positive_seconds(text: str) -> float:
    """A finite number of seconds > 0 (``nan``, ``inf`` and ``0`` refused)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"must be > 0 seconds (a finite number), got {text!r}")
    return value


def chunk_size(text: str) -> int:
    """Bytes per MCAP chunk, 1 KiB .. 256 MiB."""
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"must be a number of bytes, got {text!r}") from None
    if not 1024 <= value <= MAX_CHUNK_SIZE:
        raise ValueError(f"must be 1024..{MAX_CHUNK_SIZE} bytes (1 KiB..256 MiB), got {value}")
    return value


class Checked(argparse.Action):
    """An option whose value ``check`` converts or refuses: the usage error names the option
    (``--duration must be > 0 seconds ...``)."""

    def __init__(self, *args: object, check: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.check = check

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        try:
            setattr(namespace, self.dest, self.check(values))  # type: ignore[operator]
        except ValueError as exc:
            parser.error(f"{option_string} {exc}")


def check_output(out: Path, force: bool) -> None:
    """Refuse, before joining the run, an output path that cannot be written, naming it."""
    if out.is_dir():
        raise SystemExit(f"emos record: {out} is a directory; -o takes the path of the MCAP file to write")
    if out.exists() or out.is_symlink():
        if not force:
            raise SystemExit(f"emos record: {out} exists (use --force to overwrite)")
        if not os.access(out, os.W_OK):
            raise SystemExit(f"emos record: {out} exists and is not writable")
        return
    parent = out.parent
    if not parent.exists():
        raise SystemExit(f"emos record: cannot write {out}: the directory {parent} does not exist")
    if not parent.is_dir():
        raise SystemExit(f"emos record: cannot write {out}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SystemExit(f"emos record: cannot write {out}: the directory {parent} is not writable"
                         + (" (read-only file system)" if _read_only_fs(parent) else ""))


def _read_only_fs(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("topics", nargs="*", help="topics to record, shell wildcards allowed (default: all, new ones included)")
    parser.add_argument("-o", "--output", required=True, help="the MCAP file to write")
    parser.add_argument("-x", "--exclude", action="append", default=[], metavar="TOPIC", help="topic (or wildcard) not to record")
    parser.add_argument("--duration", action=Checked, check=positive_seconds, default=None, metavar="S",
                        help="stop after S seconds (default: until Ctrl-C or SIGTERM)")
    parser.add_argument("--compression", choices=("none", "zstd", "lz4"), default="none",
                        help="chunk compression (default none, as rosbag2: the least CPU; zstd halves camera images for ~1 ms of CPU per 640x480 frame)")
    parser.add_argument("--chunk-size", action=Checked, check=chunk_size, default=1 << 20, metavar="BYTES",
                        help="bytes per chunk, 1024..268435456 (default 1 MiB); a killed recorder loses at most one")
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
    from emos.interop.record import Recorder, default_progress, describe_os_error

    import_modules(args.imports)
    out = Path(args.output)
    check_output(out, args.force)
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
    try:
        recorder = Recorder(ctx, str(out), args.topics, args.exclude, compression=args.compression,
                            chunk_size=args.chunk_size, distribution=args.distribution, defer=args.defer_ms / 1000.0)
    except OSError as exc:
        if exc.filename is None or Path(exc.filename) != out:
            raise  # not the output file (shared memory, the run directory): not ours to explain
        raise SystemExit(f"emos record: cannot write {out}: {describe_os_error(exc)}") from None
    progress = None if args.quiet else default_progress()
    try:
        recorder.run(lambda: bool(stop), args.duration, progress)
    finally:
        recorder.close()
    if progress is not None:
        sys.stderr.write("\n")
    if recorder.failure is not None:
        print(f"emos record: {recorder.failure.message()}", file=sys.stderr)
        return 1
    stats = recorder.writer.stats
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
