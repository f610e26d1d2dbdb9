"""The control plane of components: where to reach one, what to ask it, and in which encoding.

Every component's node serves a control socket, ``<run>/ctl/<component>.sock``
(:func:`control_socket`): an :class:`~emos.core.rpc.RpcServer` (msgpack frames of at most
:data:`~emos.core.rpc.CONTROL_FRAME`, mode 0600 in the run's 0700 directory). Its operations:

=============================  ==============================================================
``get_state``, ``info``        lifecycle state, health, pid, steps; topics and config
``transition``                 one lifecycle transition (the supervisor drives these)
``execute_method``             call a public method of the component (arguments and result in
                               the wire format below); the one way to call a method, for
                               actions, fallbacks, the CLI, other runs over Zenoh
``run_step``                   one step of a component whose trigger is an Event
``update_config_parameter(s)``, ``configure_from_file``, ``change_topic``: live reconfiguration
                               (:mod:`emos.core.reconfig`)
``inject_fault``, ``clear_fault``  the chaos suite's sensor faults (:mod:`emos.core.faults`)
``exit``                       finalize and leave
=============================  ==============================================================

A component asks its supervisor (``$EMOS_SUPERVISOR_SOCKET``) with ``hello`` when it is up and
``lifecycle`` for ``self.restart()`` and the like (:func:`request_lifecycle`).

**Wire format** of method arguments and results (:func:`encode_value` / :func:`decode_value`):
msgpack values as they are; messages as their topic frame under their type name; enums by class
name (looked up among modules already imported, never imported) and value; numpy as lists.
Nothing arriving is unpickled or imported.

**Clients**: :class:`ControlClient` (blocking) and :class:`AsyncControlClient` (an event loop,
many components, one kept connection each). Both retry while nothing listens on the socket (the
component dead or restarting) for up to ``queue_timeout`` seconds, with the backoff
:data:`emos.core.rpc.UNREACHABLE_BACKOFF`, then fail with an error naming the component. A component that dies
*while* it runs a request gets it again from its next incarnation (at-least-once).

This module imports nothing of the component, the node, fallbacks, reconfiguration or actions:
they all import it.
"""
from __future__ import annotations

import asyncio
import sys
from collections.abc import Awaitable, Callable
from enum import Enum
from pathlib import Path
from typing import Any, cast

import attrs
import numpy as np

from emos.core.retry import retry, retry_async
from emos.core.rpc import UNREACHABLE_BACKOFF, AsyncRpcClient, RpcClient, RpcConnectionError
from emos.errors import EmosError
from emos.msgs import codec
from emos.msgs.registry import canonical_name, resolve
from emos.transport.context import RunContext, current, encode_name


def control_socket(ctx: RunContext, component_name: str) -> Path:
    """The control socket of component ``component_name`` in run ``ctx``."""
    return ctx.run_dir / "ctl" / f"{encode_name(component_name)}.sock"


# ============================================================================ operations
GET_STATE = "get_state"
INFO = "info"
TRANSITION = "transition"
EXECUTE_METHOD = "execute_method"
RUN_STEP = "run_step"
UPDATE_PARAMETER = "update_config_parameter"
UPDATE_PARAMETERS = "update_config_parameters"
CONFIGURE_FROM_FILE = "configure_from_file"
CHANGE_TOPIC = "change_topic"
INJECT_FAULT = "inject_fault"
CLEAR_FAULT = "clear_fault"
EXIT = "exit"

# What another run may ask over Zenoh (emos.transport.zenoh_control): what the Monitor's actions
# use, and the state. Not exit, transitions, fault injection or topic rewiring.
REMOTE_CALLS = (EXECUTE_METHOD, RUN_STEP, UPDATE_PARAMETER, UPDATE_PARAMETERS, CONFIGURE_FROM_FILE, GET_STATE)
# Names older runs send over Zenoh for an operation that has another name now. Only the Zenoh
# bridge accepts them (a run of another version may be on the network); a component's own
# socket, reached only by this installation's code, does not.
LEGACY_REMOTE_CALLS = {"run_action": EXECUTE_METHOD}

# The supervisor's operations a component (or a recipe's own code) uses.
SUPERVISOR_HELLO = "hello"
SUPERVISOR_LIFECYCLE = "lifecycle"
SUPERVISOR_STOP = "stop"  # end the whole run
SUPERVISOR_TREE = "tree"
SUPERVISOR_EVENTS = "events"
LIFECYCLE_REQUESTS = ("start", "stop", "restart")


def is_public_name(name: Any) -> bool:
    """A method name the control plane may call: a non-empty str not starting with ``_``."""
    return isinstance(name, str) and bool(name) and not name.startswith("_")


def public_method(obj: Any, name: Any, component: str) -> Callable[..., Any]:
    """``obj``'s public method ``name``, or AttributeError naming ``component`` and ``name``."""
    method: Any = getattr(obj, name, None) if is_public_name(name) else None
    if not callable(method):
        raise AttributeError(f"component {component!r} has no public method {name!r}")
    return cast("Callable[..., Any]", method)


# ============================================================================ wire format
class ActionError(EmosError, RuntimeError):
    """An action that cannot run: bad target, unencodable argument, unreachable component."""


_MSG, _ENUM = "__emos_msg__", "__emos_enum__"


def encode_value(value: Any, where: str) -> Any:
    """``value`` in the wire format; ActionError (naming ``where``) if it cannot be sent."""
    if value is None or isinstance(value, (bool, int, float, str, bytes)):
        return value
    if isinstance(value, Enum):
        return {_ENUM: f"{type(value).__module__}:{type(value).__qualname__}", "v": encode_value(value.value, where)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [encode_value(v, where) for v in value]
    if isinstance(value, dict):
        return {str(k): encode_value(v, where) for k, v in value.items()}
    if attrs.has(type(value)):
        try:
            return {_MSG: canonical_name(type(value)), "b": codec.pack(value)}
        except Exception:
            pass
    raise ActionError(f"{where}: cannot send a {type(value).__name__} to another process (messages, enums, numbers, str, lists and dicts can be sent)")


def decode_value(value: Any) -> Any:
    """The value :func:`encode_value` encoded (messages decoded, enums looked up, not imported)."""
    if isinstance(value, list):
        return [decode_value(v) for v in value]
    if isinstance(value, dict):
        if _MSG in value:
            return codec.decode(resolve(value[_MSG]), value["b"], copy=True)
        if _ENUM in value:
            module, _, qualname = str(value[_ENUM]).partition(":")
            obj: Any = sys.modules.get(module)
            for part in qualname.split("."):
                obj = getattr(obj, part, None)
            if not (isinstance(obj, type) and issubclass(obj, Enum)):
                raise ActionError(f"enum {value[_ENUM]!r} is not known in this process")
            return obj(decode_value(value["v"]))
        return {k: decode_value(v) for k, v in value.items()}
    return value


def encode_result(result: Any) -> Any:
    """What a method returned, for the answer: in the wire format, or its repr if it cannot be."""
    try:
        return encode_value(result, "result")
    except ActionError:
        return repr(result)


def decode_result(result: Any) -> Any:
    """An answer's result as objects; left encoded where this process cannot decode it (an enum
    whose module is not imported here), so a caller still gets what the method said."""
    try:
        return decode_value(result)
    except Exception:  # noqa: BLE001 - a result this process cannot rebuild is still an answer
        return result


def method_request(method: str, args: Any = (), kwargs: dict[str, Any] | None = None, where: str = "execute_method") -> dict[str, Any]:
    """The ``execute_method`` payload for ``method(*args, **kwargs)`` (arguments encoded)."""
    return {"method": method, "args": encode_value(list(args), where), "kwargs": encode_value(dict(kwargs or {}), where)}


# ============================================================================ clients
def _unreachable(what: str, op: str, queue_timeout: float, exc: BaseException) -> str:
    return f"{what} unreachable for {queue_timeout:g} s ({exc}); {op} not delivered"


def call(path: Path | str, op: str, payload: dict[str, Any] | None = None, *, timeout: float = 10.0, queue_timeout: float = 0.0,
         what: str | None = None, on_stream: Callable[[Any], None] | None = None,
         sleep: Callable[[float], Any] | None = None) -> Any:
    """One request ``op`` on the socket at ``path`` (a control socket, or a service's), blocking.

    While nothing listens there it is sent again for up to ``queue_timeout`` seconds (0: once);
    then :class:`RpcConnectionError` naming ``what``. The server's refusal is
    :class:`~emos.core.rpc.RpcError`; no answer within ``timeout`` is TimeoutError."""
    body = dict(payload or {})

    def once() -> Any:
        with RpcClient(path, timeout=timeout) as rpc:
            return rpc.call(op, on_stream=on_stream, **body)

    try:
        return retry(once, attrs.evolve(UNREACHABLE_BACKOFF, timeout=max(0.0, queue_timeout)), retry_on=RpcConnectionError, sleep=sleep)
    except RpcConnectionError as exc:
        if queue_timeout <= 0:
            raise
        raise RpcConnectionError(_unreachable(what or str(path), op, queue_timeout, exc)) from None


class ControlClient:
    """Blocking calls on one component's control socket, from any process of the run:

        ControlClient("planner").execute_method("set_goal", goal)

    ``queue_timeout``: seconds to keep trying while the component does not listen (0: fail at
    once)."""

    def __init__(self, component: str, ctx: RunContext | None = None, *, timeout: float = 15.0, queue_timeout: float = 0.0):
        self.component = component
        self.path = control_socket(ctx or current(), component)
        self.timeout = timeout
        self.queue_timeout = queue_timeout

    def call(self, op: str, timeout: float | None = None, **payload: Any) -> Any:
        return call(self.path, op, payload, timeout=self.timeout if timeout is None else timeout, queue_timeout=self.queue_timeout,
                    what=f"component {self.component!r}")

    def execute_method(self, method: str, *args: Any, **kwargs: Any) -> Any:
        """``method(*args, **kwargs)`` run in the component, between two of its steps."""
        where = f"{self.component}.{method}()"
        return decode_result(self.call(EXECUTE_METHOD, **method_request(method, args, kwargs, where)))


class AsyncControlClient:
    """Calls on the control sockets of a run's components from one event loop (the Monitor's,
    the supervisor's fallback driver): one connection per component, kept between calls.

    A call on a component that is dead or restarting is not lost: it waits, queued, for the
    next incarnation, for up to ``queue_timeout`` seconds, then raises :class:`ActionError`
    naming the component (the caller reports it)."""

    def __init__(self, ctx: RunContext, queue_timeout: float = 10.0, sleep: Callable[[float], Awaitable[Any]] | None = None):
        self.ctx = ctx
        self.queue_timeout = queue_timeout
        self._sleep = sleep
        self._clients: dict[str, AsyncRpcClient] = {}

    async def call(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        async def once() -> Any:
            client = self._clients.get(component)
            if client is None:
                client = self._clients[component] = AsyncRpcClient(control_socket(self.ctx, component))
            try:
                return await client.call(op, timeout=timeout, **payload)
            except RpcConnectionError:
                await client.close()  # a new incarnation listens on a new connection
                if self._clients.get(component) is client:
                    del self._clients[component]
                raise

        try:
            return await retry_async(once, attrs.evolve(UNREACHABLE_BACKOFF, timeout=max(0.0, self.queue_timeout)),
                                     retry_on=RpcConnectionError, sleep=self._sleep)
        except RpcConnectionError as exc:
            raise ActionError(_unreachable(f"component {component!r}", op, self.queue_timeout, exc)) from None

    async def execute_method(self, component: str, method: str, args: Any = (), kwargs: dict[str, Any] | None = None,
                             timeout: float = 10.0) -> Any:
        """``method(*args, **kwargs)`` in ``component``; the result as the component encoded it."""
        where = f"{component}.{method}()"
        return await self.call(component, EXECUTE_METHOD, timeout, **method_request(method, args, kwargs, where))

    async def close(self) -> None:
        for client in self._clients.values():
            await client.close()
        self._clients.clear()


def request_lifecycle(node: Any, op: str, wait_time: float = 0.0) -> None:
    """From inside a component (``self.restart()``): ask the supervisor, without waiting for it
    (a restart ends this very process). ``node``: the component's running node."""
    loop = node.loop
    if loop is None or node.supervisor_socket is None:
        raise RuntimeError(f"component {node.name!r}: no supervisor to ask for {op}")

    async def ask() -> None:
        client = AsyncRpcClient(node.supervisor_socket)
        try:
            await client.call(SUPERVISOR_LIFECYCLE, component=node.name, request=op, wait_time=wait_time, wait=False, by="component", timeout=10.0)
        except Exception as exc:
            node.log.error("[%s] %s request to the supervisor failed: %s", node.name, op, exc)
        finally:
            await client.close()

    loop.call_soon_threadsafe(lambda: asyncio.ensure_future(ask()))


__all__ = [
    "control_socket", "GET_STATE", "INFO", "TRANSITION", "EXECUTE_METHOD", "RUN_STEP", "UPDATE_PARAMETER", "UPDATE_PARAMETERS",
    "CONFIGURE_FROM_FILE", "CHANGE_TOPIC", "INJECT_FAULT", "CLEAR_FAULT", "EXIT", "REMOTE_CALLS", "LEGACY_REMOTE_CALLS",
    "SUPERVISOR_HELLO", "SUPERVISOR_LIFECYCLE", "SUPERVISOR_STOP", "SUPERVISOR_TREE", "SUPERVISOR_EVENTS", "LIFECYCLE_REQUESTS", "UNREACHABLE_BACKOFF", "is_public_name", "public_method",
    "ActionError", "encode_value", "decode_value", "encode_result", "decode_result", "method_request", "call", "ControlClient",
    "AsyncControlClient", "request_lifecycle",
]
