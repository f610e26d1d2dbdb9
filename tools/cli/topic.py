"""``emos topic list|echo|hz|pub``: look at and feed the topics of a running system.

``pub`` checks what it is given before it publishes anything: the numbers of its options at
argument parsing, the message's fields against the type (one line naming the field and what it
expects), and the type against the topic's publishers and, when it has none, against the
components that read it (each component's control socket says what its inputs are).

Every command first removes the wake-up files of readers killed without closing (an earlier
``emos topic echo`` that got SIGKILL), so ``list`` counts only live subscribers.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

import attrs

from emos.core.rpc import RpcClient, RpcConnectionError, RpcError
from emos.errors import EmosError
from emos.msgs import codec
from emos.msgs import fields as F
from emos.msgs.registry import UnknownMessageType, canonical_name, resolve
from emos.tools.cli.common import add_run_argument, exit_if_terminated, join_run, options_anywhere, signals_deferred
from emos.transport.context import decode_name
from emos.transport.pubsub import Publisher, Subscriber, list_topics
from emos.transport.waker import Waker, sweep_dead_wakers

MIN_RATE_HZ = 1e-6  # once in 11.6 days; a slower "rate" is a typo, and its period overflows sleep()
INFO_TIMEOUT_S = 3.0  # per component asked which topics it reads; bounds a hung one


# ---------------------------------------------------------------------------------- option values
def _number(option: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{option} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{option} must be a finite number, got {text!r}")
    return value


def _whole(option: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{option} must be a whole number, got {text!r}") from None


def rate_hz(text: str) -> float:
    value = _number("--rate", text)
    if value < MIN_RATE_HZ:
        raise argparse.ArgumentTypeError(f"--rate must be a rate in Hz of at least {MIN_RATE_HZ:g}, got {text!r} "
                                         "(leave it out to publish the messages back to back)")
    return value


def _at_least(option: str, low: int, meaning: str = ""):
    def parse(text: str) -> int:
        value = _whole(option, text)
        if value < low:
            raise argparse.ArgumentTypeError(f"{option} must be {low} or more{meaning}, got {text!r}")
        return value

    return parse


def _seconds(option: str, positive: bool):
    def parse(text: str) -> float:
        value = _number(option, text)
        if value < 0 or (positive and value == 0):
            raise argparse.ArgumentTypeError(f"{option} must be {'more than 0' if positive else '0 or more'} seconds, got {text!r}")
        return value

    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True)
    verbs = []
    p = sub.add_parser("list", help="topics, their types, publishers and subscribers")
    verbs.append(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("--network", metavar="ZENOH_CONFIG", nargs="?", const="", default=None,
                   help="only the topics published over Zenoh by any host of the group ($EMOS_NET_GROUP), "
                        "through this Zenoh configuration file (default: $EMOS_ZENOH_CONFIG; with neither, only the "
                        "loopback sessions of this host and user); needs no local run")
    p = sub.add_parser("echo", help="print messages as they arrive")
    verbs.append(p)
    p.add_argument("topic")
    p.add_argument("--count", "-n", type=_at_least("--count", 0, " (0: no limit)"), default=0, help="stop after N messages (default 0: no limit)")
    p.add_argument("--timeout", type=_seconds("--timeout", positive=False), default=0.0, help="stop after S seconds (default 0: no limit)")
    p.add_argument("--arrays", type=_at_least("--arrays", 0), default=8, help="print at most this many array elements")
    p = sub.add_parser("hz", help="measure the publishing rate")
    verbs.append(p)
    p.add_argument("topic")
    p.add_argument("--window", type=_seconds("--window", positive=True), default=2.0, help="seconds per report")
    p.add_argument("--reports", type=_at_least("--reports", 0, " (0: no limit)"), default=0, help="stop after N reports (default 0: no limit)")
    p = sub.add_parser("pub", help="publish a message given as JSON (or YAML) fields")
    verbs.append(p)
    p.add_argument("topic")
    p.add_argument("msg_type")
    p.add_argument("fields", nargs="?", default="{}", help='e.g. \'{"data": 1.5}\'')
    p.add_argument("--rate", type=rate_hz, default=None,
                   help="publish repeatedly at this rate in Hz (a finite number > 0); without it, the messages go out back to back")
    p.add_argument("--count", "-n", type=_at_least("--count", 0, " (0: until Ctrl-C)"), default=1,
                   help="number of messages (default 1; 0 = until Ctrl-C or SIGTERM)")
    from emos.tools.cli import topic_plot as cli_topic_plot

    p = sub.add_parser("plot", help="plot numeric fields over time, live or saved (--output FILE)")
    verbs.append(p)
    cli_topic_plot.add_arguments(p)
    options_anywhere(parser, verbs, add_run_argument)  # --run before or after the verb


class BadMessage(EmosError, ValueError):
    """FIELDS or MSG_TYPE of ``emos topic pub`` that cannot make a message (one-line reason)."""


def _parse_fields(text: str, what: str = "FIELDS") -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as json_exc:
        import yaml

        try:
            return yaml.safe_load(text)
        except yaml.YAMLError as exc:
            where = getattr(exc, "problem_mark", None)
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            at = f" at line {where.line + 1} column {where.column + 1}" if where is not None else ""
            raise BadMessage(f"{what} {text!r} is neither JSON ({json_exc.msg} at column {json_exc.colno}) nor YAML ({problem}{at})") from None


def _field_path(cls: type, data: dict, prefix: str = "") -> str:
    """The dotted path (``linear`` of a Twist) of the innermost nested message in ``data`` that
    does not build; '' if the problem is at the top."""
    try:
        known = attrs.fields_dict(cls)
    except (TypeError, attrs.exceptions.NotAnAttrsClassError):
        return prefix
    for name, value in data.items():
        field = known.get(name)
        if field is None or field.metadata.get("kind") not in (F.MESSAGE, F.OPTIONAL_MESSAGE) or not isinstance(value, dict):
            continue
        inner = field.metadata["cls"]()
        try:
            codec.from_builtin(inner, value)
        except (TypeError, ValueError, OverflowError):
            return _field_path(inner, value, f"{prefix}{name}.")
    return prefix


def build_message(type_name: str | type, text: str, what: str = "FIELDS") -> Any:
    """The message ``emos topic pub`` was asked for (and ``emos service call`` / ``emos action
    send_goal``, whose ``what`` is REQUEST / GOAL); BadMessage says in one line what is wrong,
    naming the field and what it expects."""
    try:
        cls = resolve(type_name)
    except UnknownMessageType as exc:
        raise BadMessage(f"MSG_TYPE: {exc.args[0] if exc.args else exc} (e.g. String, Twist, std_msgs/msg/Float64)") from None
    fields = _parse_fields(text, what)
    if fields is None:
        fields = {}
    name = canonical_name(cls)
    if not isinstance(fields, dict):
        names = ", ".join(f.name for f in attrs.fields(cls))
        raise BadMessage(f"{what} must be a JSON (or YAML) mapping of {name} fields ({names}), "
                         f"e.g. '{{\"field\": value}}'; got {type(fields).__name__} {text!r}")
    try:
        return codec.from_builtin(cls, fields)
    except (TypeError, ValueError, OverflowError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        path = _field_path(cls, fields)
        # The converters name the field by its own class (Vector3.x); say where it is (linear.x).
        owned = re.match(r"^\w+\.(\w+) (expects .*)$", reason)
        if path and owned:
            reason = f"field {path}{owned.group(1)} {owned.group(2)}"
        elif owned:
            reason = f"field {owned.group(1)} {owned.group(2)}"
        elif path:
            reason = f"in field {path.rstrip('.')}: {reason}"
        raise BadMessage(f"bad {what} for {name}: {reason}") from None


def _normal(topic: str) -> str:
    return topic if topic.startswith("/") else "/" + topic


def readers_of(ctx, topic: str) -> dict[str, str]:
    """``{component: message type}`` of the components of the run that read ``topic``, from
    each one's control socket (a component that does not answer in time is skipped)."""
    readers: dict[str, str] = {}
    try:
        sockets = sorted((ctx.run_dir / "ctl").glob("*.sock"))
    except OSError:
        return readers
    for path in sockets:
        try:
            with RpcClient(path, timeout=INFO_TIMEOUT_S) as rpc:
                info = rpc.call("info")
        except (RpcConnectionError, RpcError, TimeoutError, OSError, ValueError):
            continue
        inputs = info.get("inputs") if isinstance(info, dict) else None
        if not isinstance(inputs, dict):
            continue
        component = info.get("component")
        component = component if isinstance(component, str) else decode_name(path.stem).lstrip("/")
        for name, type_name in inputs.items():
            if isinstance(name, str) and isinstance(type_name, str) and _normal(name) == topic:
                readers[component] = type_name
    return readers


def check_publish_type(ctx, topic: str, cls: type) -> str | None:
    """Why ``cls`` must not be published on ``topic`` (its publishers or readers use another type)."""
    ours = canonical_name(cls)
    existing = list_topics(ctx).get(topic)
    if existing is not None and existing["type"] != "?":
        if existing["type"] == ours:
            return None
        return (f"{topic} carries {existing['type']} (publishers: {', '.join(existing['publishers'])}), "
                f"not {ours}; its subscribers would reject every message")
    wrong = {}
    for component, type_name in readers_of(ctx, topic).items():
        try:
            theirs = canonical_name(resolve(type_name))
        except UnknownMessageType:
            theirs = type_name
        if theirs != ours:
            wrong[component] = theirs
    if not wrong:
        return None
    said = "; ".join(f"{topic} is read as {theirs} by {component}" for component, theirs in sorted(wrong.items()))
    return f"{said}; you asked to publish {ours}"


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
            bridged = f"  ros2 ({info['ros2']['direction']} {info['ros2']['type']})" if "ros2" in info else ""
            print(f"{name:<40} {info['type']:<40} pubs={len(info['publishers'])} subs={info.get('subscribers', 0)}{bridged}")
    return 0


def _with_ros2_marks(ctx, topics: dict) -> dict:
    """Marks the topics the run's ROS 2 bridge carries (``<run dir>/ros2_bridge.json``, written by
    the bridge: read as untrusted, a bad file only loses the marks), and adds those components
    carry on the ROS 2 graph themselves (``transport="ros2"``: no ring, so not listed otherwise)."""
    from emos.interop.ros2.direct import direct_records
    from emos.interop.ros2.options import STATE_FILE

    for name, record in direct_records(ctx).items():
        topics[name] = {"type": record["type"], "publishers": record["pub"], "subscribers": len(record["sub"]), "transport": "ros2",
                        "ros2": {"direction": "direct", "type": record["type"]}}
    try:
        state = json.loads((Path(ctx.run_dir) / STATE_FILE).read_text())
        bridged = state["topics"] if isinstance(state, dict) and isinstance(state.get("topics"), dict) else {}
    except (OSError, ValueError):
        return topics
    for name, info in bridged.items():
        if name in topics and isinstance(info, dict) and isinstance(info.get("direction"), str) and isinstance(info.get("type"), str):
            topics[name]["ros2"] = {"direction": info["direction"], "type": info["type"]}
    return topics


def _short(value, n: int):
    if isinstance(value, dict):
        return {k: _short(v, n) for k, v in value.items()}
    if isinstance(value, list):
        return [_short(v, n) for v in value[:n]] + ([f"... ({len(value)} items)"] if len(value) > n else [])
    return value


def run(args: argparse.Namespace) -> int:
    if args.action == "list" and getattr(args, "network", None) is not None:
        from emos.transport.zenoh_net import close_sessions
        from emos.transport.zenoh_net import list_topics as network_topics

        try:
            topics = network_topics(config_path=args.network or None)
        finally:
            close_sessions()
        return _print_topics(topics, args.json)
    msg = None
    if args.action == "pub":
        # What was asked for is checked before looking for a system: the answer does not depend on one.
        try:
            msg = build_message(args.msg_type, args.fields)
        except BadMessage as exc:
            print(f"emos topic pub: {exc}", file=sys.stderr)
            return 2
    ctx = join_run(args.run)
    sweep_dead_wakers(ctx)  # readers killed outright left theirs (module doc)
    if args.action == "list":
        return _print_topics(_with_ros2_marks(ctx, list_topics(ctx)), args.json)
    topic = args.topic if args.topic.startswith("/") else "/" + args.topic
    if args.action == "pub":
        cls = type(msg)
        refusal = check_publish_type(ctx, topic, cls)
        if refusal is not None:
            raise SystemExit(f"emos topic pub: {refusal}")
        pub = None
        sent = 0
        period = 1.0 / args.rate if args.rate else 0.0
        try:
            # Inside the try: a signal held during construction is delivered as the block ends,
            # and the ring it made must still be removed by the finally below.
            with signals_deferred():
                try:
                    pub = Publisher(ctx, topic, cls)
                except ValueError as exc:  # a topic name that cannot be a segment name
                    raise SystemExit(f"emos topic pub: {exc}") from None
            due = time.monotonic()
            while args.count == 0 or sent < args.count:
                exit_if_terminated()
                pub.publish(msg)
                sent += 1
                if period and (args.count == 0 or sent < args.count):
                    due += period  # drift-free: the rate holds however long a publish took
                    time.sleep(max(0.0, due - time.monotonic()))
            time.sleep(0.05)  # let subscribers copy the last message before the ring goes away
        finally:
            if pub is not None:
                with signals_deferred():
                    pub.close()
        print(f"published {sent} {cls.__name__} on {topic}")
        return 0
    cls = _topic_type(ctx, topic)
    if args.action == "plot":
        from emos.tools.cli import topic_plot as cli_topic_plot

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
                exit_if_terminated()
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
                exit_if_terminated()
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
