"""``emos topic list|echo|hz|pub``: look at and feed the topics of a running system."""
from __future__ import annotations

import argparse
import json
import time

from emos.msgs import codec
from emos.msgs.registry import canonical_name, resolve
from emos.supervisor.cli_common import add_run_argument, join_run, signals_deferred
from emos.transport.pubsub import Publisher, Subscriber, list_topics
from emos.transport.waker import Waker


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True)
    p = sub.add_parser("list", help="topics, their types, publishers and subscribers")
    add_run_argument(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("--network", metavar="ZENOH_CONFIG", nargs="?", const="", default=None,
                   help="only the topics published over Zenoh by any host of the group ($EMOS_NET_GROUP), "
                        "through this Zenoh configuration file (default: $EMOS_ZENOH_CONFIG); needs no local run")
    p = sub.add_parser("echo", help="print messages as they arrive")
    add_run_argument(p)
    p.add_argument("topic")
    p.add_argument("--count", "-n", type=int, default=0, help="stop after N messages")
    p.add_argument("--timeout", type=float, default=0.0, help="stop after S seconds")
    p.add_argument("--arrays", type=int, default=8, help="print at most this many array elements")
    p = sub.add_parser("hz", help="measure the publishing rate")
    add_run_argument(p)
    p.add_argument("topic")
    p.add_argument("--window", type=float, default=2.0, help="seconds per report")
    p.add_argument("--reports", type=int, default=0, help="stop after N reports")
    p = sub.add_parser("pub", help="publish a message given as JSON (or YAML) fields")
    add_run_argument(p)
    p.add_argument("topic")
    p.add_argument("msg_type")
    p.add_argument("fields", nargs="?", default="{}", help='e.g. \'{"data": 1.5}\'')
    p.add_argument("--rate", type=float, default=0.0, help="publish repeatedly at this rate (Hz)")
    p.add_argument("--count", "-n", type=int, default=1, help="number of messages (0 = until Ctrl-C)")
    from emos.supervisor import cli_topic_plot

    p = sub.add_parser("plot", help="plot numeric fields over time, live or saved (--output FILE)")
    add_run_argument(p)
    cli_topic_plot.add_arguments(p)


def _topic_type(ctx, topic: str) -> type:
    info = list_topics(ctx).get(topic if topic.startswith("/") else "/" + topic)
    if info is None or info["type"] == "?":
        raise SystemExit(f"emos topic: no publisher on {topic!r} yet (see `emos topic list`)")
    return resolve(info["type"])


def _print_topics(topics: dict, as_json: bool) -> int:
    if as_json:
        print(json.dumps(topics, indent=2))
    else:
        for name, info in sorted(topics.items()):
            print(f"{name:<40} {info['type']:<40} pubs={len(info['publishers'])} subs={info.get('subscribers', 0)}")
    return 0


def _short(value, n: int):
    if isinstance(value, dict):
        return {k: _short(v, n) for k, v in value.items()}
    if isinstance(value, list):
        return [_short(v, n) for v in value[:n]] + ([f"... ({len(value)} items)"] if len(value) > n else [])
    return value


def run(args: argparse.Namespace) -> int:
    if args.action == "list" and getattr(args, "network", None) is not None:
        from emos.transport.zenoh_net import close_sessions, list_topics as network_topics

        try:
            topics = network_topics(config_path=args.network or None)
        finally:
            close_sessions()
        return _print_topics(topics, args.json)
    ctx = join_run(args.run)
    if args.action == "list":
        topics = list_topics(ctx)
        if args.json:
            print(json.dumps(topics, indent=2))
        else:
            for name, info in sorted(topics.items()):
                print(f"{name:<40} {info['type']:<40} pubs={len(info['publishers'])} subs={info.get('subscribers', 0)}")
        return 0
    topic = args.topic if args.topic.startswith("/") else "/" + args.topic
    if args.action == "pub":
        cls = resolve(args.msg_type)
        try:
            fields = json.loads(args.fields)
        except json.JSONDecodeError:
            import yaml

            fields = yaml.safe_load(args.fields)
        msg = codec.from_builtin(cls, fields or {})
        existing = list_topics(ctx).get(topic)
        if existing is not None and existing["type"] not in ("?", canonical_name(cls)):
            raise SystemExit(
                f"emos topic pub: {topic} carries {existing['type']} (publishers: {', '.join(existing['publishers'])}), "
                f"not {canonical_name(cls)}; its subscribers would reject every message"
            )
        pub = None
        sent = 0
        try:
            # Inside the try: a signal held during construction is delivered as the block ends,
            # and the ring it made must still be removed by the finally below.
            with signals_deferred():
                pub = Publisher(ctx, topic, cls)
            while args.count == 0 or sent < args.count:
                pub.publish(msg)
                sent += 1
                if args.rate <= 0 and args.count == 1:
                    break
                time.sleep(1.0 / args.rate if args.rate > 0 else 0.0)
            time.sleep(0.05)  # let subscribers copy the last message before the ring goes away
        finally:
            if pub is not None:
                with signals_deferred():
                    pub.close()
        print(f"published {sent} {cls.__name__} on {topic}")
        return 0
    cls = _topic_type(ctx, topic)
    if args.action == "plot":
        from emos.supervisor import cli_topic_plot

        return cli_topic_plot.run(args, ctx, topic, cls)
    import select

    waker = sub = None
    try:
        with signals_deferred():
            waker = Waker(ctx)
            sub = Subscriber(ctx, topic, cls, waker=waker, queue_size=1000)
        if args.action == "echo":
            seen, t_end = 0, time.monotonic() + args.timeout if args.timeout else None
            while (not args.count or seen < args.count) and (t_end is None or time.monotonic() < t_end):
                select.select([waker.fd], [], [], 0.2)
                waker.drain()
                for msg in sub.take():
                    print(json.dumps(_short(codec.to_builtin(msg), args.arrays), default=str))
                    print("---", flush=True)
                    seen += 1
            return 0
        reports = 0
        while not args.reports or reports < args.reports:
            stamps: list[int] = []
            t_end = time.monotonic() + args.window
            while time.monotonic() < t_end:
                select.select([waker.fd], [], [], 0.1)
                waker.drain()
                stamps.extend(stamp for stamp, _, _ in sub.take_raw())
            reports += 1
            if len(stamps) < 2:
                print(f"{topic}: no messages in {args.window:g} s", flush=True)
                continue
            gaps = [(b - a) / 1e9 for a, b in zip(stamps, stamps[1:])]
            mean = sum(gaps) / len(gaps)
            print(f"{topic}: {1 / mean:.2f} Hz  min {min(gaps) * 1e3:.2f} ms  max {max(gaps) * 1e3:.2f} ms  n={len(stamps)}", flush=True)
        return 0
    finally:
        with signals_deferred():
            if sub is not None:
                sub.close()
            if waker is not None:
                waker.close()
