"""Services and actions across hosts: a Zenoh queryable in front of each local server.

A component's services and actions keep serving on their Unix sockets (see
:mod:`emos.core.services`); when the run shares them over the network (``$EMOS_NET_SERVICES``:
``all`` or names separated by ``,``; ``emos run --net-services``), the node also declares a
:class:`NetServiceBridge` on ``emos/<group>/_srv_/<name>``. A query there carries a msgpack map
``{"op": "call" | "goal" | "cancel", ...}`` with the request or goal in EMOS's message encoding;
the bridge forwards it to the local socket on a thread of its own (a goal may run for minutes)
and replies: once for a service (``{"ok": response}``), once per feedback and once with the
result for an action (Zenoh lets a queryable reply several times to one query). Errors come back
as Zenoh error replies carrying the server's message.

:class:`NetServiceClient` and :class:`NetActionClient` are the calling side, usable from any
process that can open a Zenoh session into the group (no run needed).
"""
from __future__ import annotations

import logging
import os
import threading
import uuid
from collections.abc import Callable
from typing import Any

import msgpack

from emos.core.rpc import RpcClient
from emos.core.services import ActionCanceled, service_socket
from emos.errors import EmosError, TransportError
from emos.msgs import codec
from emos.msgs.registry import resolve
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext
from emos.transport.zenoh_net import KEY_ROOT, ROUTING_TURNS, _zenoh, net_group, session

log = logging.getLogger("emos.transport.zenoh")
ENV_NET_SERVICES = "EMOS_NET_SERVICES"
SRV_MARK = "_srv_"
_OPS = {"service": ("call",), "action": ("goal", "cancel")}
_warn = RateLimitedLog(log, interval=10.0)


class RemoteServiceError(EmosError, RuntimeError):
    """The remote server answered with an error (its message is kept)."""


class ServiceUnavailable(TransportError, TimeoutError):
    """No host of the group answered: no server declared there (yet), or the query timed out."""


def service_key(name: str, group: str | None = None) -> str:
    path = name.strip("/")
    if not path or any(ch in path for ch in "*$?#@") or "//" in path:
        raise ValueError(f"service {name!r} cannot be a Zenoh key expression (no '*', '$', '?', '#', '@' or empty parts)")
    return f"{KEY_ROOT}/{group or net_group()}/{SRV_MARK}/{path}"


def shared_over_network(name: str) -> bool:
    """Whether the run shares service or action ``name`` over Zenoh (``$EMOS_NET_SERVICES``)."""
    raw = os.environ.get(ENV_NET_SERVICES, "").strip()
    if not raw:
        return False
    if raw == "all":
        return True
    wanted = {"/" + part.strip().strip("/") for part in raw.split(",") if part.strip()}
    return "/" + name.strip("/") in wanted


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


class QueryBridge:
    """A Zenoh queryable on ``key`` in front of something local (a Unix socket), serving each
    query on a thread of its own (forwarding blocks for as long as the request runs).

    The query's payload is untrusted: it must be a msgpack map whose ``op`` is one of ``ops``,
    else the caller gets an error reply and a rate-limited warning names the key; nothing a
    query carries can raise out of here. Subclasses implement :meth:`handle` (reply with
    ``query.reply(self.key, _pack(...))``; raise to reply an error)."""

    what = "query"
    MAX_CONCURRENT = 32  # queries served at once; more are refused at once (a flood must not spawn threads without end)

    def __init__(self, key: str, ops: tuple[str, ...], config_path: str | None = None, label: str = ""):
        self.key, self.ops, self.label = key, ops, label or key
        self._slots = threading.BoundedSemaphore(self.MAX_CONCURRENT)
        with ROUTING_TURNS:
            self._queryable = session(config_path).declare_queryable(key, self._on_query)

    def _on_query(self, query: Any) -> None:
        if not self._slots.acquire(blocking=False):
            with query:
                self._refuse(query, RuntimeError(f"busy: {self.MAX_CONCURRENT} queries already being served"))
            return
        try:
            threading.Thread(target=self._serve, args=(query,), name=f"emos-net:{self.label}", daemon=True).start()
        except BaseException:
            self._slots.release()
            raise

    def _serve(self, query: Any) -> None:
        try:
            with query:  # the query is finalised (the caller's get ends) when this block is left
                try:
                    self.handle(query, self._parse(query))
                except Exception as exc:  # noqa: BLE001 - every failure goes back to the caller
                    self._refuse(query, exc)
        finally:
            self._slots.release()

    def _refuse(self, query: Any, exc: BaseException) -> None:
        _warn.warning(f"q:{self.key}", "%s %s over Zenoh (%s): %s: %s", self.what, self.label, self.key, type(exc).__name__, exc)
        try:
            query.reply_err(_pack({"error": f"{type(exc).__name__}: {exc}"}))
        except Exception as reply_exc:  # noqa: BLE001 - the caller may have gone
            log.debug("%s %s: error reply failed: %s", self.what, self.label, reply_exc)

    def _parse(self, query: Any) -> dict[str, Any]:
        payload = query.payload
        if payload is None:
            raise ValueError("a query without a payload")
        try:
            req = msgpack.unpackb(payload.to_bytes(), raw=False)
        except Exception as exc:  # noqa: BLE001 - foreign bytes
            raise ValueError(f"a payload that is not msgpack: {exc}") from None
        if not isinstance(req, dict) or req.get("op") not in self.ops:
            raise ValueError(f"a {self.what} accepts ops {self.ops}, got {str(req)[:80]}")
        return req

    def handle(self, query: Any, req: dict[str, Any]) -> None:
        raise NotImplementedError

    def close(self) -> None:
        queryable, self._queryable = self._queryable, None
        if queryable is not None:
            try:
                with ROUTING_TURNS:
                    queryable.undeclare()
            except Exception as exc:  # noqa: BLE001 - the session may be gone already
                log.debug("%s %s: undeclaring: %s", self.what, self.label, exc)


def timeout_of(req: dict[str, Any], default: float, limit: float) -> float:
    """The ``timeout`` a remote request asks for, as a number in (0, limit], else ``default``."""
    value = req.get("timeout", default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= limit:
        raise ValueError(f"timeout must be a number of seconds in (0, {limit:g}], got {value!r}")
    return float(value)


class NetServiceBridge(QueryBridge):
    """Serves the local service or action ``name`` (``kind``) to the Zenoh group."""

    def __init__(self, ctx: RunContext, name: str, kind: str, config_path: str | None = None):
        if kind not in _OPS:
            raise ValueError(f"bridge kind must be 'service' or 'action', got {kind!r}")
        self.name, self.kind, self.what = name, kind, kind
        self.path = service_socket(ctx, name)
        super().__init__(service_key(name), _OPS[kind], config_path, label=name)

    def handle(self, query: Any, req: dict[str, Any]) -> None:
        op = req["op"]
        if op == "call":
            with RpcClient(self.path, timeout=timeout_of(req, 10.0, 24 * 3600.0)) as rpc:
                raw = rpc.call("call", request=req["request"])
            query.reply(self.key, _pack({"ok": raw}))
        elif op == "goal":
            def feedback(frame: Any) -> None:
                if isinstance(frame, dict) and "feedback" in frame:
                    query.reply(self.key, _pack({"feedback": frame["feedback"]}))

            with RpcClient(self.path, timeout=timeout_of(req, 3600.0, 7 * 24 * 3600.0)) as rpc:
                reply = rpc.call("goal", on_stream=feedback, goal=req["goal"], goal_id=str(req.get("goal_id") or uuid.uuid4().hex))
            query.reply(self.key, _pack({"result": reply["result"], "canceled": bool(reply.get("canceled"))}))
        else:  # cancel
            with RpcClient(self.path, timeout=5.0) as rpc:
                done = bool(rpc.call("cancel", goal_id=str(req.get("goal_id"))))
            query.reply(self.key, _pack({"ok": done}))


def _replies(key: str, request: dict[str, Any], timeout: float, config_path: str | None) -> Any:
    zenoh = _zenoh()
    return session(config_path).get(
        key, payload=_pack(request), timeout=timeout, target=zenoh.QueryTarget.BEST_MATCHING,
        consolidation=zenoh.ConsolidationMode.NONE,  # every feedback reply, in order
    )


def _unpack_reply(name: str, reply: Any) -> dict[str, Any]:
    if reply.ok is None:
        try:
            detail = msgpack.unpackb(reply.err.payload.to_bytes(), raw=False).get("error", "?")
        except Exception:  # noqa: BLE001
            detail = "an error reply that is not an EMOS one"
        raise RemoteServiceError(f"{name}: {detail}")
    data = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
    if not isinstance(data, dict):
        raise RemoteServiceError(f"{name}: a reply that is not an EMOS one")
    return data


class NetServiceClient:
    """``NetServiceClient("/planner/plan", Req, Resp).call(req)``: a service on any host of the group."""

    def __init__(self, name: str, request_type: Any, response_type: Any, timeout: float = 10.0, config_path: str | None = None):
        self.name = name
        self.request_type, self.response_type = resolve(request_type), resolve(response_type)
        self.key, self.timeout, self.config_path = service_key(name), timeout, config_path

    def call(self, request: Any, timeout: float | None = None) -> Any:
        if not isinstance(request, self.request_type):
            raise TypeError(f"service {self.name!r} takes {self.request_type.__name__}, got {type(request).__name__}")
        timeout = timeout or self.timeout
        for reply in _replies(self.key, {"op": "call", "request": codec.pack(request), "timeout": timeout}, timeout, self.config_path):
            data = _unpack_reply(f"service {self.name!r}", reply)
            return codec.decode(self.response_type, data["ok"], copy=True)
        raise ServiceUnavailable(f"service {self.name!r}: no host of group {net_group()!r} answered on {self.key} within {timeout} s")


class NetActionClient:
    """Send a goal to an action on any host of the group; feedback through a callback."""

    def __init__(self, name: str, goal_type: Any, feedback_type: Any, result_type: Any, config_path: str | None = None):
        self.name = name
        self.goal_type, self.feedback_type, self.result_type = resolve(goal_type), resolve(feedback_type), resolve(result_type)
        self.key, self.config_path = service_key(name), config_path

    def send_goal(self, goal: Any, feedback_callback: Callable[[Any], None] | None = None, timeout: float = 3600.0, goal_id: str | None = None) -> Any:
        if not isinstance(goal, self.goal_type):
            raise TypeError(f"action {self.name!r} takes goals of {self.goal_type.__name__}, got {type(goal).__name__}")
        goal_id = goal_id or uuid.uuid4().hex
        request = {"op": "goal", "goal": codec.pack(goal), "goal_id": goal_id, "timeout": timeout}
        for reply in _replies(self.key, request, timeout, self.config_path):
            data = _unpack_reply(f"action {self.name!r}", reply)
            if "feedback" in data:
                if feedback_callback is not None:
                    feedback_callback(codec.decode(self.feedback_type, data["feedback"], copy=True))
                continue
            if data.get("canceled"):
                raise ActionCanceled(f"action {self.name!r}: goal {goal_id} was canceled")
            return codec.decode(self.result_type, data["result"], copy=True)
        raise ServiceUnavailable(f"action {self.name!r}: no result from group {net_group()!r} on {self.key} within {timeout} s")

    def cancel(self, goal_id: str, timeout: float = 5.0) -> bool:
        for reply in _replies(self.key, {"op": "cancel", "goal_id": goal_id}, timeout, self.config_path):
            return bool(_unpack_reply(f"action {self.name!r}", reply).get("ok"))
        raise ServiceUnavailable(f"action {self.name!r}: no host of group {net_group()!r} answered the cancel on {self.key} within {timeout} s")
