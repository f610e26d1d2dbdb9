"""Components' control across hosts: what a Monitor of another run uses to act on them.

A run started with ``--zenoh`` serves, from its Zenoh helper (:mod:`emos.transport.zenoh_status`),
one queryable per component on ``emos/<group>/_ctl_/<component>`` (a
:class:`~emos.transport.zenoh_rpc.QueryBridge` in front of the run's Unix sockets). A query is a
msgpack map; ``op`` says what to reach:

``control``    one operation of the component's control socket (``call``), among
               :data:`CONTROL_CALLS` only: a public method (``execute_method``; older runs call it
               ``run_action``, which is accepted too), a step, parameters, a config file, its
               state. Not ``exit``, fault injection or topic rewiring.
``lifecycle``  ``start`` / ``stop`` / ``restart`` (``request``) through the run's supervisor, so a
               remote restart counts against the restart intensity like a local one.
``service``    a request to one of the run's services (``name``, ``request`` in EMOS's encoding).
``goal``       a goal to one of the run's action servers, sent and not waited for (as the local
               ``send_component_action_server_goal``): the reply says it was handed over.

The reply is ``{"ok": result}``, or an error reply with the reason: a malformed query, an
operation not offered, a component that stays unreachable for the request's ``timeout`` (it is
retried meanwhile, as a local action waits for a restarting component), the component's own
error. Component names are global in a group (as topic names are), so the run that has the
component answers, and only it.

:class:`RemoteControl` is the calling side (the Monitor's, :mod:`emos.supervisor.monitor_net`).
Served only when the run asks for it (``emos run --net-control``, ``$EMOS_NET_CONTROL=on``), as
services are only with ``--net-services``: then every session that joins the group's Zenoh
network may call; restrict who joins with Zenoh's own access control and TLS in the
configuration file.
"""
from __future__ import annotations

import logging
import os
import threading
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import attrs

from emos.core import control as C
from emos.core.retry import Backoff, retry
from emos.core.rpc import RpcClient
from emos.transport.context import RunContext
from emos.transport.zenoh_net import KEY_ROOT, net_group
from emos.transport.zenoh_rpc import QueryBridge, RemoteServiceError, ServiceUnavailable, _pack, _replies, _unpack_reply, timeout_of

log = logging.getLogger("emos.transport.zenoh")
ENV_NET_CONTROL = "EMOS_NET_CONTROL"
CTL_MARK = "_ctl_"
OPS = ("control", "lifecycle", "service", "goal")
# The control-socket operations another run may ask for (emos.core.control.REMOTE_CALLS), and the
# names older runs use for some of them.
CONTROL_CALLS = C.REMOTE_CALLS + tuple(C.LEGACY_REMOTE_CALLS)
LIFECYCLE_REQUESTS = C.LIFECYCLE_REQUESTS
_RESERVED_ARGS = ("id", "op", "timeout", "on_stream")  # the socket frame's and RpcClient.call's own
MAX_TIMEOUT_S = 3600.0
MAX_WAIT_S = 3600.0
MAX_GOALS = 16  # goals from other runs running at once per component; more are refused
# Asking again while no run answers (its helper starting, the link coming up): up to twice a second.
NO_ANSWER_BACKOFF = Backoff(base=0.05, factor=2.0, cap=0.5, timeout=0.0)


def control_key(component: str, group: str | None = None) -> str:
    name = component.strip("/")
    if not name or any(ch in name for ch in "*$?#@/"):
        raise ValueError(f"component {component!r} cannot be a Zenoh key part (no '*', '$', '?', '#', '@', '/' or empty name)")
    return f"{KEY_ROOT}/{group or net_group()}/{CTL_MARK}/{name}"


def control_enabled() -> bool:
    """Whether this run serves its components' control to the group (``$EMOS_NET_CONTROL``)."""
    value = os.environ.get(ENV_NET_CONTROL, "off").strip().lower()
    if value not in ("on", "off", "1", "0", "true", "false", ""):
        raise ValueError(f"${ENV_NET_CONTROL} must be 'on' or 'off', got {value!r}")
    return value in ("on", "1", "true")


def _str(req: dict[str, Any], field: str, allowed: Iterable[str] | None = None) -> str:
    value = req.get(field)
    if not isinstance(value, str) or not value:
        raise ValueError(f"{field!r} must be a non-empty str, got {type(value).__name__}")
    if allowed is not None and value not in allowed:
        raise ValueError(f"{field!r} must be one of {tuple(allowed)}, got {value[:60]!r}")
    return value


def _bytes(req: dict[str, Any], field: str) -> bytes:
    value = req.get(field)
    if not isinstance(value, bytes):
        raise ValueError(f"{field!r} must be bytes (an EMOS-encoded message), got {type(value).__name__}")
    return value


class ComponentControl(QueryBridge):
    """The queryable of one component of this run (in the run's Zenoh helper)."""

    what = "control"

    def __init__(self, ctx: RunContext, component: str, config_path: str | None = None):
        self.ctx, self.component = ctx, component
        self.control_path = C.control_socket(ctx, component)
        self.supervisor_path = ctx.run_dir / "supervisor.sock"
        self._goals = threading.BoundedSemaphore(MAX_GOALS)
        super().__init__(control_key(component), OPS, config_path, label=component)

    def handle(self, query: Any, req: dict[str, Any]) -> None:
        op = req["op"]
        timeout = timeout_of(req, 10.0, MAX_TIMEOUT_S)
        if op == "control":
            asked = _str(req, "call", CONTROL_CALLS)
            call = C.LEGACY_REMOTE_CALLS.get(asked, asked)
            args = req.get("args", {})
            if not isinstance(args, dict) or not all(isinstance(k, str) and k not in _RESERVED_ARGS for k in args):
                raise ValueError(f"'args' must be a map of str keys other than {', '.join(_RESERVED_ARGS)}")
            method = args.get("method")
            if call == C.EXECUTE_METHOD and not C.is_public_name(method):
                # Another run may call what a recipe may name: a public method, never the internals
                # (the component refuses them too; said here before anything is forwarded).
                raise ValueError(f"{asked} from another run calls only a public method, got {str(method)[:60]!r}")
            result = self._retrying(self.control_path, call, timeout, args)
        elif op == "lifecycle":
            request = _str(req, "request", LIFECYCLE_REQUESTS)
            wait = req.get("wait_time", 0.0)
            if isinstance(wait, bool) or not isinstance(wait, (int, float)) or not 0 <= wait <= MAX_WAIT_S:  # NaN fails too
                raise ValueError(f"'wait_time' must be a number of seconds in [0, {MAX_WAIT_S:g}], got {wait!r}")
            with RpcClient(self.supervisor_path, timeout=timeout + float(wait) + 30.0) as rpc:
                result = rpc.call(C.SUPERVISOR_LIFECYCLE, component=self.component, request=request, wait_time=float(wait), by="remote")
        elif op == "service":
            result = self._retrying(self._server_socket(req), "call", timeout, {"request": _bytes(req, "request")})
        else:  # goal: handed over, not waited for (a goal may run for minutes)
            path, goal = self._server_socket(req), _bytes(req, "goal")
            goal_id = str(req.get("goal_id") or uuid.uuid4().hex)[:64]
            if not self._goals.acquire(blocking=False):
                raise RuntimeError(f"busy: {MAX_GOALS} goals from other runs already running for {self.component}")
            try:
                threading.Thread(target=self._goal, args=(path, goal, goal_id), name=f"emos-net-goal:{self.component}", daemon=True).start()
            except BaseException:
                self._goals.release()
                raise
            result = goal_id
        query.reply(self.key, _pack({"ok": result}))

    def _server_socket(self, req: dict[str, Any]) -> Path:
        from emos.core.services import service_socket

        name = _str(req, "name")
        if len(name) > 256 or any(ch in name for ch in "\0\n"):
            raise ValueError(f"'name' is not a service name: {name[:60]!r}")
        return service_socket(self.ctx, name)

    def _retrying(self, path: Path, call: str, timeout: float, args: dict[str, Any]) -> Any:
        """``call`` on ``path``, retried while nothing listens there (a component restarting)
        for up to ``timeout`` seconds, as a local action waits for the next incarnation."""
        return C.call(path, call, args, timeout=timeout, queue_timeout=timeout, what=f"component {self.component!r}")

    def _goal(self, path: Path, goal: bytes, goal_id: str) -> None:
        try:
            with RpcClient(path, timeout=MAX_TIMEOUT_S) as rpc:
                rpc.call("goal", goal=goal, goal_id=goal_id)
        except Exception as exc:  # noqa: BLE001 - nobody waits for it: say it here
            log.error("goal %s for %s (from another run over Zenoh) failed: %s: %s", goal_id, self.component, type(exc).__name__, exc)
        finally:
            self._goals.release()


class ControlBridges:
    """One :class:`ComponentControl` per component of the run, following the supervision tree."""

    def __init__(self, ctx: RunContext, config_path: str | None = None):
        self.ctx, self.config_path = ctx, config_path
        self._bridges: dict[str, ComponentControl] = {}

    def watch(self, components: Iterable[str]) -> None:
        wanted = set(components)
        for name in sorted(set(self._bridges) - wanted):
            self._bridges.pop(name).close()
        for name in sorted(wanted - set(self._bridges)):
            try:
                self._bridges[name] = ComponentControl(self.ctx, name, self.config_path)
            except ValueError as exc:  # a name that cannot be a key part
                log.warning("component %s cannot be controlled over Zenoh: %s", name, exc)

    @property
    def components(self) -> list[str]:
        return sorted(self._bridges)

    def close(self) -> None:
        for bridge in self._bridges.values():
            bridge.close()
        self._bridges.clear()


class RemoteControl:
    """Send control requests to components of other runs of the group (blocking; the Monitor
    calls it from a worker thread)."""

    def __init__(self, config_path: str | None = None, group: str | None = None):
        self.config_path, self.group = config_path, group

    def request(self, component: str, req: dict[str, Any], timeout: float) -> Any:
        """Send ``req`` and return the reply's result. While no run answers (its helper starting,
        the network link coming up), ask again for up to ``timeout`` seconds, as a local action
        waits for a restarting component; then :class:`ServiceUnavailable`. An error reply raises
        :class:`RemoteServiceError` at once."""
        key = control_key(component, self.group)
        what = f"component {component!r} ({req.get('op')} {req.get('call') or req.get('request') or req.get('name') or ''})"
        # Zenoh's own deadline leaves the remote side its whole ``timeout`` (and a restart its wait).
        wait = timeout + float(req.get("wait_time") or 0.0) + (30.0 if req.get("op") == "lifecycle" else 2.0)

        def ask() -> Any:
            for reply in _replies(key, {**req, "timeout": timeout}, wait, self.config_path):
                return _unpack_reply(what, reply).get("ok")
            raise ServiceUnavailable(f"component {component!r}: no run of group {self.group or net_group()!r} answered on {key} "
                                     f"for {timeout:g} s (is it running, with --zenoh, and is its control on?)")

        # An error reply (RemoteServiceError) is the component's answer: raised at once.
        return retry(ask, attrs.evolve(NO_ANSWER_BACKOFF, timeout=timeout), retry_on=ServiceUnavailable)


__all__ = ["ComponentControl", "ControlBridges", "RemoteControl", "RemoteServiceError", "ServiceUnavailable", "control_key",
           "control_enabled", "CONTROL_CALLS"]
