"""``emos action send_goal COMPONENT ACTION '{...}'`` and ``emos action list [COMPONENT]``: the
actions components serve (``ros2 action send_goal`` and ``ros2 action list -t``).

``send_goal`` finds the action in the component's own description (:mod:`.interfaces`), builds
the goal from the JSON (or YAML) fields and checks it against the goal type before anything is
sent, then sends it with the :class:`~emos.core.services.ActionClient` recipes use. It prints,
on stdout, one line per event, each a label and one line of JSON::

    sending goal 5f0c... to /planner/plan_path
    feedback: {"distance_to_goal": 2.1, "plan_length": 2.4}
    result: {"success": true, "message": "goal reached", ...}
    goal finished: succeeded

Ctrl-C (SIGINT), SIGTERM or ``--timeout`` cancel the goal on the component: the command asks
until the component acknowledges the cancel, waits (at most ``--cancel-timeout``) for the goal to
end, prints its last result and ``goal finished: canceled``, and exits 130 (SIGINT), 143 (SIGTERM)
or 1 (timeout). A goal is never left running behind a command that has gone. A second Ctrl-C
stops waiting for the goal to end.

Exit codes: 0 the goal ran to its end (whatever its result says), 1 not found, unreachable,
failed in the component, canceled by someone else, or --timeout; 2 a bad goal; 130/143 as above.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
import uuid
from typing import Any

from emos.core.rpc import RpcConnectionError, RpcError
from emos.core.services import ActionCanceled, ActionClient
from emos.msgs import codec
from emos.tools.cli.common import add_run_argument, exit_if_terminated, join_run, options_anywhere, signals_deferred
from emos.tools.cli.interfaces import InterfaceError, find, listing, print_listing
from emos.tools.cli.record import add_import_argument, import_modules
from emos.tools.cli.topic import BadMessage, build_message

EXAMPLES = """examples:
  emos action list
  emos action send_goal planner plan_path '{"goal": {"position": {"x": 2.0, "y": 3.0}}}'
  emos action send_goal controller track_vision_target '{"label": "person"}' --timeout 60
  emos action send_goal vla vision_language_action '{"task": "pick up the cube"}'   # Ctrl-C cancels the goal
"""
POLL_S = 0.2  # how often the waiting main thread looks at SIGTERM and --timeout
FOREVER_S = 365 * 86400.0  # the goal's socket waits this long for its next frame: no limit in practice


def _seconds(option: str, allow_zero: bool):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"{option} must be a finite number of seconds {'>= 0' if allow_zero else '> 0'}, got {text!r}")
        return value

    return parse


def _shared(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    sub = parser.add_subparsers(dest="verb", required=True, metavar="{send_goal,list}")
    send = sub.add_parser("send_goal", help="send a goal, print its feedback and result; Ctrl-C cancels it",
                          description="send a goal to a component's action, print its feedback as it arrives and its "
                                      "result; Ctrl-C cancels the goal on the component")
    send.add_argument("component", help="component name (see `emos component list`)")
    send.add_argument("action", help="action name, full (/planner/plan_path) or within the component (plan_path)")
    send.add_argument("goal", nargs="?", default="{}", help='goal fields as JSON (or YAML), e.g. \'{"label": "person"}\' (default {})')
    send.add_argument("--timeout", type=_seconds("--timeout", allow_zero=True), default=0.0,
                      help="cancel the goal if it has not ended after S seconds (default 0: no limit)")
    send.add_argument("--cancel-timeout", type=_seconds("--cancel-timeout", allow_zero=False), default=30.0,
                      help="after a cancel, wait at most S seconds for the goal to end (default %(default)s)")
    send.add_argument("--no-feedback", action="store_true", help="do not print the feedback")
    add_import_argument(send)
    listed = sub.add_parser("list", help="the actions of a component (or of all) with their types (as `ros2 action list -t`)")
    listed.add_argument("component", nargs="?", default=None, help="component name (default: every component of the run)")
    listed.add_argument("--json", action="store_true", help="print the list as JSON")
    listed.add_argument("--timeout", type=_seconds("--timeout", allow_zero=False), default=15.0,
                        help="seconds to wait for each component's answer (default %(default)s)")
    options_anywhere(parser, [send, listed], _shared)  # --run before or after the verb


def _line(label: str, msg: Any) -> None:
    print(f"{label}: {json.dumps(codec.to_builtin(msg), default=str)}", flush=True)


class _Goal:
    """One goal in flight on a thread of its own, so the main thread stays free for signals.
    Made first, started inside the block that handles Ctrl-C: a signal can land anywhere, and a
    goal that may have gone out must be canceled (``started`` says whether it may have)."""

    def __init__(self, client: ActionClient, goal: Any, goal_id: str, show_feedback: bool):
        self.client, self.goal_id = client, goal_id
        self.done = threading.Event()
        self.result: Any = None
        self.canceled = False
        self.error: BaseException | None = None

        def feedback(msg: Any) -> None:
            if show_feedback:
                _line("feedback", msg)

        def work() -> None:
            try:
                self.result = client.send_goal(goal, feedback_callback=feedback, timeout=FOREVER_S, goal_id=goal_id)
            except ActionCanceled as exc:
                self.canceled, self.result = True, exc.result
            except BaseException as exc:  # noqa: BLE001 - handed to the main thread, which reports it
                self.error = exc
            finally:
                self.done.set()

        self.thread = threading.Thread(target=work, name="emos-action-goal", daemon=True)

    def start(self) -> None:
        self.thread.start()

    @property
    def started(self) -> bool:
        return self.thread.ident is not None


def _cancel(goal: _Goal, action: str, why: str, cancel_timeout: float) -> bool:
    """Cancel the goal and wait for it to end; whether it ended within ``cancel_timeout``."""
    print(f"emos action send_goal: {why}: canceling goal {goal.goal_id}", file=sys.stderr, flush=True)
    deadline = time.monotonic() + cancel_timeout
    acknowledged = False
    try:
        # False means the server does not know the goal (yet: the goal frame may still be on its
        # way, or no longer: it just ended); ask again until it knows it or the goal has ended.
        while not goal.done.is_set() and time.monotonic() < deadline:
            try:
                acknowledged = goal.client.cancel(goal.goal_id)
            except (RpcConnectionError, RpcError, TimeoutError) as exc:
                print(f"emos action send_goal: the cancel did not reach {action}: {exc}", file=sys.stderr, flush=True)
                break
            if acknowledged:
                print(f"emos action send_goal: cancel acknowledged by {action}", file=sys.stderr, flush=True)
                break
            goal.done.wait(0.05)
        goal.done.wait(max(0.0, deadline - time.monotonic()))
    except KeyboardInterrupt:
        print(f"emos action send_goal: interrupted again: not waiting for goal {goal.goal_id} to end", file=sys.stderr, flush=True)
        return False
    if not goal.done.is_set():
        print(f"emos action send_goal: goal {goal.goal_id} did not end within {cancel_timeout:g} s of the cancel "
              f"(--cancel-timeout); the component may still be running it", file=sys.stderr, flush=True)
        return False
    return True


def _finish(goal: _Goal, where: str, asked_to_cancel: bool) -> int:
    """Print how the goal ended; the exit code when nobody asked to cancel it."""
    if goal.error is not None:
        exc = goal.error
        if isinstance(exc, RpcConnectionError):
            print(f"{where}: the action is not reachable or the component went away ({exc})", file=sys.stderr)
        elif isinstance(exc, RpcError):
            print(f"{where}: the goal failed in the component: {exc}", file=sys.stderr)
        else:
            print(f"{where}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    if goal.result is not None:
        _line("result", goal.result)
    if goal.canceled:
        print("goal finished: canceled" + ("" if asked_to_cancel else " (not by this command)"), flush=True)
        return 1
    print("goal finished: succeeded", flush=True)
    return 0


def run_send_goal(args: argparse.Namespace) -> int:
    ctx = join_run(args.run)
    import_modules(args.imports)
    where = f"emos action send_goal {args.component} {args.action}"
    try:
        iface = find(ctx, args.component, "action", args.action, 15.0)
        goal_type, feedback_type, result_type = (iface.message_class(role) for role in ("goal", "feedback", "result"))
    except InterfaceError as exc:
        print(f"emos action send_goal: {exc}", file=sys.stderr)
        return 1
    try:
        goal_msg = build_message(goal_type, args.goal, "GOAL")
    except BadMessage as exc:
        print(f"{where}: {exc}", file=sys.stderr)
        return 2
    client = ActionClient(iface.name, goal_type, feedback_type, result_type, ctx=ctx)
    goal = _Goal(client, goal_msg, uuid.uuid4().hex, not args.no_feedback)
    deadline = time.monotonic() + args.timeout if args.timeout else math.inf
    try:
        with signals_deferred():  # a signal comes after the start, never half way through it
            goal.start()
            # Said once it is on its way: a Ctrl-C after this line cancels the goal on the component.
            print(f"sending goal {goal.goal_id} to {iface.shown}", flush=True)
        while not goal.done.wait(POLL_S):
            exit_if_terminated()
            if time.monotonic() >= deadline:
                ended = _cancel(goal, iface.shown, f"no result within {args.timeout:g} s (--timeout)", args.cancel_timeout)
                if ended:
                    _finish(goal, where, asked_to_cancel=True)
                return 1
    except KeyboardInterrupt:
        code, why = 130, "interrupted (Ctrl-C)"
    except SystemExit as stop:  # SIGTERM (the CLI's handler raises it)
        code, why = (stop.code if isinstance(stop.code, int) else 143), "terminated"
    else:
        return _finish(goal, where, asked_to_cancel=False)
    if not goal.started:
        print(f"emos action send_goal: {why} before the goal was sent", file=sys.stderr, flush=True)
        return code
    if _cancel(goal, iface.shown, why, args.cancel_timeout):
        _finish(goal, where, asked_to_cancel=True)
    return code


def run(args: argparse.Namespace) -> int:
    if args.verb == "send_goal":
        return run_send_goal(args)
    ctx = join_run(args.run)
    try:
        found, problems = listing(ctx, args.component, "action", args.timeout)
    except InterfaceError as exc:
        print(f"emos action list: {exc}", file=sys.stderr)
        return 1
    for problem in problems:
        print(f"emos action list: {problem}", file=sys.stderr)
    print_listing(found, args.json)
    return 0
