"""``emos service call COMPONENT SERVICE '{...}'`` and ``emos service list [COMPONENT]``: the
services components serve (``ros2 service call`` and ``ros2 service list -t``).

``call`` finds the service in the component's own description (:mod:`.interfaces`), builds the
request from the JSON (or YAML) fields and checks it against the request type before anything
is sent (a bad field is named with what it expects), calls it with the
:class:`~emos.core.services.ServiceClient` recipes use, and prints the response as JSON.
Exit codes: 0 answered, 1 not found, unreachable or failed in the component, 2 a bad request.
"""
from __future__ import annotations

import argparse
import json
import sys

from emos.core.rpc import RpcConnectionError, RpcError
from emos.core.services import ServiceClient
from emos.msgs import codec
from emos.tools.cli.common import join_run
from emos.tools.cli.interfaces import InterfaceError, find, listing, print_listing
from emos.tools.cli.record import add_import_argument, import_modules
from emos.tools.cli.topic import BadMessage, build_message

CALL_EXAMPLES = """examples:
  emos service call planner start_path_recording '{"recording_time_step": 0.2}'
  emos service call planner /planner/save_plan_to_file '{"file_location": "/tmp", "file_name": "path.csv"}'
  emos service list planner
"""


def add_call_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = CALL_EXAMPLES
    p.add_argument("component", help="component name (see `emos component list`)")
    p.add_argument("service", help="service name, full (/planner/save_plan_to_file) or within the component (save_plan_to_file)")
    p.add_argument("request", nargs="?", default="{}", help='request fields as JSON (or YAML), e.g. \'{"file_name": "p.csv"}\' (default {})')
    add_import_argument(p)


def add_list_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("component", nargs="?", default=None, help="component name (default: every component of the run)")
    p.add_argument("--json", action="store_true", help="print the list as JSON")


def run_call(args: argparse.Namespace) -> int:
    ctx = join_run(args.run)
    import_modules(args.imports)
    where = f"emos service call {args.component} {args.service}"
    try:
        iface = find(ctx, args.component, "service", args.service, args.timeout)
        request_type, response_type = iface.message_class("request"), iface.message_class("response")
    except InterfaceError as exc:
        print(f"emos service call: {exc}", file=sys.stderr)
        return 1
    try:
        request = build_message(request_type, args.request, "REQUEST")
    except BadMessage as exc:
        print(f"{where}: {exc}", file=sys.stderr)
        return 2
    client = ServiceClient(iface.name, request_type, response_type, ctx=ctx, timeout=args.timeout)
    try:
        response = client.call(request)
    except RpcConnectionError as exc:
        print(f"{where}: the service is not reachable ({exc}); is the component still active?", file=sys.stderr)
        return 1
    except RpcError as exc:
        print(f"{where}: the component failed to answer: {exc}", file=sys.stderr)
        return 1
    except TimeoutError:
        print(f"{where}: no answer within {args.timeout:g} s (--timeout)", file=sys.stderr)
        return 1
    finally:
        client.close()
    print(json.dumps(codec.to_builtin(response), indent=2, default=str))
    return 0


def run_list(args: argparse.Namespace) -> int:
    ctx = join_run(args.run)
    try:
        found, problems = listing(ctx, args.component, "service", args.timeout)
    except InterfaceError as exc:
        print(f"emos service list: {exc}", file=sys.stderr)
        return 1
    for problem in problems:
        print(f"emos service list: {problem}", file=sys.stderr)
    print_listing(found, args.json)
    return 0
