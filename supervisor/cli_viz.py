"""``emos viz``: serve a running system's topics to Foxglove (WebSocket protocol)."""
from __future__ import annotations

import argparse

from emos.supervisor.cli_common import add_run_argument, join_run
from emos.supervisor.cli_record import add_import_argument, check_distribution, import_modules, stop_flag


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("topics", nargs="*", help="topics to serve, wildcards allowed (default: all, new ones included)")
    parser.add_argument("-x", "--exclude", action="append", default=[], metavar="TOPIC", help="topic (or wildcard) not to serve")
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0 exposes the robot's data to the network)")
    parser.add_argument("--port", type=int, default=8765, help="WebSocket port (default 8765, Foxglove's default)")
    parser.add_argument("--distribution", default="humble", help="ROS 2 distribution of the cdr channels' type definitions (default humble)")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    add_import_argument(parser)


def run(args: argparse.Namespace) -> int:
    from emos.interop.foxglove_bridge import FoxgloveBridge
    from emos.interop.record import default_progress

    import_modules(args.imports)
    if not 0 <= args.port <= 65535:
        raise SystemExit(f"emos viz: --port must be 0..65535, got {args.port}")
    check_distribution("emos viz", args.distribution)
    ctx = join_run(args.run)
    stop = stop_flag()
    try:
        bridge = FoxgloveBridge(ctx, args.host, args.port, args.topics, args.exclude, distribution=args.distribution)
    except OSError as exc:
        raise SystemExit(f"emos viz: {exc}") from exc
    print(f"Foxglove: open ws://{args.host}:{bridge.port} in Foxglove (Open connection > Foxglove WebSocket)", flush=True)
    try:
        bridge.serve(lambda: bool(stop), None if args.quiet else default_progress())
    finally:
        bridge.close()
    return 0
