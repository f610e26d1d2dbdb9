"""``emos component``: talk to one component of the running system.

    emos component list
    emos component info NAME
    emos component call NAME SERVICE [key=value ...]

SERVICE is one of the live-reconfiguration services every component serves:
``update_config_parameter name=loop_rate value=5 [keep_alive=false]``,
``update_config_parameters names=loop_rate,fallback_rate values=5,10``,
``configure_from_file path=conf.yaml``,
``change_topic direction=0 old_name=/scan new_name=/scan_front [new_msg_type=LaserScan]``,
``execute_method method=NAME [args=...]``; or a lifecycle request: ``start``, ``stop``, ``restart``
(through the supervisor). Values are parsed as YAML scalars (``5`` is an int, ``true`` a bool,
``[1, 2]`` a list); the component's config validates them and refuses bad ones with its message.
The services and actions a component declares itself (the Planner's ``save_plan_to_file``, its
``plan_path`` action) are called with ``emos service call`` and ``emos action send_goal``.

``--run`` and ``--timeout`` go before or after the verb. Without ``--run`` the one live run is
used (a line on stderr names it); with several live runs the command lists them and stops.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import yaml

from emos.core import control as C
from emos.core.discovery import component_workers
from emos.core.rpc import RpcClient, RpcConnectionError, RpcError
from emos.tools.cli.common import add_run_argument, join_run, options_anywhere

SERVICES = (C.UPDATE_PARAMETER, C.UPDATE_PARAMETERS, C.CONFIGURE_FROM_FILE, C.CHANGE_TOPIC, C.EXECUTE_METHOD)
LIFECYCLE = ("start", "stop", "restart")


def _shared(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("--timeout", type=float, default=15.0, help="seconds to wait for the answer (default %(default)s)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", required=True, metavar="{list,info,call}")
    verbs = [
        sub.add_parser("list", help="the components of the run"),
        sub.add_parser("info", help="one component's state, topics, config, services and actions"),
        sub.add_parser("call", help="call a reconfiguration service or a lifecycle request of a component"),
    ]
    for verb in verbs[1:]:
        verb.add_argument("name", help="component name (see `emos component list`)")
    verbs[2].add_argument("service", help=f"one of {', '.join(SERVICES + LIFECYCLE)}")
    verbs[2].add_argument("params", nargs="*", metavar="key=value")
    options_anywhere(parser, verbs, _shared)  # --run and --timeout before or after the verb


def parse_params(pairs: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, raw = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"parameters are key=value, got {pair!r}")
        try:
            value = yaml.safe_load(raw) if raw else ""
        except yaml.YAMLError as exc:
            raise ValueError(f"{key}: cannot parse {raw!r}: {exc}") from None
        out[key] = value
    return out


def _as_list(value: Any) -> list:
    if isinstance(value, list):
        return value
    if isinstance(value, str):
        return [yaml.safe_load(v) for v in value.split(",")]
    return [value]


def request(service: str, params: dict[str, Any]) -> dict[str, Any]:
    """The control-socket payload of a service call from CLI parameters."""
    if service == "update_config_parameters" and "names" in params:
        names = [str(n) for n in _as_list(params.pop("names"))]
        values = _as_list(params.pop("values", []))
        if len(names) != len(values):
            raise ValueError(f"update_config_parameters: {len(names)} names but {len(values)} values")
        params["values"] = dict(zip(names, values))
    if service == "execute_method" and "args" in params:
        params["args"] = _as_list(params["args"])
    return params


def run(args: argparse.Namespace) -> int:
    ctx = join_run(args.run)
    if args.verb == "list":
        with RpcClient(ctx.run_dir / "supervisor.sock", timeout=args.timeout) as rpc:
            tree = rpc.call("tree")["tree"]
        for name in component_workers(tree):
            print(name)
        return 0
    if args.verb == "info":
        return _call(C.control_socket(ctx, args.name), C.INFO, {}, args.timeout, args.name)
    if args.service in LIFECYCLE:
        return _call(ctx.run_dir / "supervisor.sock", C.SUPERVISOR_LIFECYCLE, {"component": args.name, "request": args.service, "by": "cli"}, args.timeout, args.name)
    if args.service not in SERVICES:
        sys.exit(f"emos component call: SERVICE must be one of {', '.join(SERVICES + LIFECYCLE)}, got {args.service!r} "
                 f"(a service of the component's own: `emos service call {args.name} {args.service} '{{...}}'`)")
    try:
        payload = request(args.service, parse_params(args.params))
    except ValueError as exc:
        sys.exit(f"emos component call {args.name} {args.service}: {exc}")
    return _call(C.control_socket(ctx, args.name), args.service, payload, args.timeout, args.name)


def _call(path: Any, op: str, payload: dict, timeout: float, name: str) -> int:
    try:
        result = C.call(path, op, payload, timeout=timeout)
    except RpcConnectionError as exc:
        print(f"emos: component {name!r} is not reachable: {exc}", file=sys.stderr)
        return 1
    except RpcError as exc:
        print(f"emos: {name} {op} refused: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(C.decode_result(result), indent=2, default=repr))
    return 0

