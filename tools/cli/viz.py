"""``emos viz``: serve a running system's topics to Foxglove (WebSocket protocol)."""
from __future__ import annotations

import argparse
import os
import sys

from emos.tools.cli.common import add_run_argument, join_run
from emos.tools.cli.record import add_import_argument, check_distribution, import_modules, stop_flag


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("topics", nargs="*", help="topics to serve, wildcards allowed (default: all, new ones included)")
    parser.add_argument("-x", "--exclude", action="append", default=[], metavar="TOPIC", help="topic (or wildcard) not to serve")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (default 127.0.0.1; any other address offers the robot's data to the network "
                             "and requires --token)")
    parser.add_argument("--port", type=int, default=8765, help="WebSocket port (default 8765, Foxglove's default)")
    parser.add_argument("--token", default=os.environ.get("EMOS_FOXGLOVE_TOKEN") or None, metavar="TOKEN|auto",
                        help="require this token of every client (ws://HOST:PORT/?token=TOKEN); 'auto' makes a random one "
                             "and prints the URL once (default: $EMOS_FOXGLOVE_TOKEN; other local users can read a "
                             "command line, not your environment)")
    parser.add_argument("--allow-origin", dest="allow_origins", action="append", default=[], metavar="ORIGIN",
                        help="also accept browser pages of this origin, scheme://host[:port], host may start with '*.', "
                             "port may be '*', or an exact origin such as file:// (repeatable; always accepted: "
                             "https://app.foxglove.dev, https://*.foxglove.dev and localhost, 127.0.0.1, [::1] on any port; "
                             "a refused handshake is logged with its origin)")
    parser.add_argument("--distribution", default="humble", help="ROS 2 distribution of the cdr channels' type definitions (default humble)")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    add_import_argument(parser)


def run(args: argparse.Namespace) -> int:
    from emos.hosts import is_loopback
    from emos.interop.foxglove_bridge import FoxgloveBridge
    from emos.interop.foxglove_gate import OriginPattern, make_token
    from emos.interop.record import default_progress

    import_modules(args.imports)
    if not 0 <= args.port <= 65535:
        raise SystemExit(f"emos viz: --port must be 0..65535, got {args.port}")
    try:
        token = make_token(args.token)
        for origin in args.allow_origins:
            OriginPattern(origin)
    except ValueError as exc:
        raise SystemExit(f"emos viz: {exc}") from exc
    if not is_loopback(args.host) and token is None:
        raise SystemExit(f"emos viz: --host {args.host} offers every topic (camera frames included) to the network: "
                         "give --token TOKEN or --token auto")
    check_distribution("emos viz", args.distribution)
    ctx = join_run(args.run)
    stop = stop_flag()
    try:
        bridge = FoxgloveBridge(ctx, args.host, args.port, args.topics, args.exclude, distribution=args.distribution,
                                token=token, allow_origins=args.allow_origins)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"emos viz: {exc}") from exc
    if not is_loopback(args.host):
        sys.stderr.write(f"emos viz: WARNING: listening on {args.host}: every machine that can reach port {bridge.port} and "
                         "knows the token gets every topic, camera frames included; the traffic is not encrypted\n")
    print(f"Foxglove: open {bridge.url()} in Foxglove (Open connection > Foxglove WebSocket)", flush=True)
    try:
        bridge.serve(lambda: bool(stop), None if args.quiet else default_progress())
    finally:
        bridge.close()
    return 0
