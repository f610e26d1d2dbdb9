"""Services (request/response) and actions (goal, feedback, result, cancel) between processes.

Each service or action listens on its own socket ``<run>/srv/<name>.sock``; requests, responses,
goals, feedback and results are messages in the topic frame format. Action goals run in a
thread of the serving component so its event loop keeps publishing status (heartbeats) while a
long goal executes; a hung goal therefore shows up as ALGORITHM or COMPONENT failure reported
by the component, not as a dead process.
"""
from __future__ import annotations

import asyncio
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import attrs

from emos.core.retry import retry, retry_async
from emos.core.rpc import UNREACHABLE_BACKOFF, AsyncRpcClient, RpcClient, RpcServer, RpcUnreachable
from emos.errors import EmosError
from emos.msgs import codec
from emos.msgs.registry import UnknownMessageType, canonical_name, resolve
from emos.transport.context import RunContext, current, encode_name


def service_socket(ctx: RunContext, name: str) -> Path:
    return ctx.run_dir / "srv" / f"{encode_name(name)}.sock"


class ServiceServer:
    def __init__(self, ctx: RunContext, name: str, request_type: Any, response_type: Any, callback: Callable[[Any], Any], owner: str = ""):
        self.name = name
        self.request_type = resolve(request_type)
        self.response_type = resolve(response_type)
        self.callback = callback
        self.server = RpcServer(service_socket(ctx, name), {"call": self._call, "describe": self._describe}, name=f"{owner}:{name}")

    async def _describe(self, req: dict[str, Any], stream: Any) -> dict[str, Any]:
        return {"request": self.request_type.__name__, "response": self.response_type.__name__}

    async def _call(self, req: dict[str, Any], stream: Any) -> bytes:
        request = codec.decode(self.request_type, req["request"])
        response = self.callback(request)
        if asyncio.iscoroutine(response):
            response = await response
        if not isinstance(response, self.response_type):
            raise TypeError(f"service {self.name!r} callback returned {type(response).__name__}, expected {self.response_type.__name__}")
        return codec.pack(response)

    async def start(self) -> None:
        await self.server.start()

    async def close(self) -> None:
        await self.server.close()


class ServiceClient:
    """Blocking client: ``ServiceClient("/planner/plan", PlanRequest, PlanResponse).call(req)``."""

    def __init__(self, name: str, request_type: Any, response_type: Any, ctx: RunContext | None = None, timeout: float = 10.0):
        self.name = name
        self.request_type = resolve(request_type)
        self.response_type = resolve(response_type)
        self.rpc = RpcClient(service_socket(ctx or current(), name), timeout=timeout)

    def call(self, request: Any, timeout: float | None = None) -> Any:
        if not isinstance(request, self.request_type):
            raise TypeError(f"service {self.name!r} takes {self.request_type.__name__}, got {type(request).__name__}")
        raw = self.rpc.call("call", timeout=timeout, request=codec.pack(request))
        return codec.decode(self.response_type, raw, copy=True)

    def close(self) -> None:
        self.rpc.close()


class GoalHandle:
    """What an action callback receives: the goal, a feedback channel and the cancel flag."""

    def __init__(self, goal_id: str, goal: Any, publish: Callable[[Any], None]):
        self.goal_id = goal_id
        self.goal = goal
        self._publish = publish
        self._cancel = threading.Event()

    def publish_feedback(self, feedback: Any) -> None:
        self._publish(feedback)

    @property
    def is_cancel_requested(self) -> bool:
        return self._cancel.is_set()

    def request_cancel(self) -> None:
        self._cancel.set()


class ActionCanceled(EmosError):
    """Raised to the client when its goal ended because it was canceled; ``result`` is what the
    server returned when it stopped (the CLI prints it, as ``ros2 action send_goal`` does)."""

    def __init__(self, message: str, result: Any = None):
        super().__init__(message)
        self.result = result


class ActionServer:
    def __init__(self, ctx: RunContext, name: str, goal_type: Any, feedback_type: Any, result_type: Any, callback: Callable[[GoalHandle], Any], owner: str = ""):
        self.name = name
        self.goal_type, self.feedback_type, self.result_type = resolve(goal_type), resolve(feedback_type), resolve(result_type)
        self.callback = callback
        self.goals: dict[str, GoalHandle] = {}
        self.server = RpcServer(service_socket(ctx, name), {"goal": self._goal, "cancel": self._cancel}, name=f"{owner}:{name}")

    async def _goal(self, req: dict[str, Any], stream: Any) -> dict[str, Any]:
        loop = asyncio.get_running_loop()
        goal_id = str(req.get("goal_id") or uuid.uuid4())
        goal = codec.decode(self.goal_type, req["goal"], copy=True)

        def publish(feedback: Any) -> None:
            if not isinstance(feedback, self.feedback_type):
                raise TypeError(f"action {self.name!r} feedback must be {self.feedback_type.__name__}, got {type(feedback).__name__}")
            payload = codec.pack(feedback)
            asyncio.run_coroutine_threadsafe(stream.send({"feedback": payload}), loop)

        handle = GoalHandle(goal_id, goal, publish)
        self.goals[goal_id] = handle
        try:
            result = await loop.run_in_executor(None, self.callback, handle)
        finally:
            self.goals.pop(goal_id, None)
        if not isinstance(result, self.result_type):
            raise TypeError(f"action {self.name!r} callback returned {type(result).__name__}, expected {self.result_type.__name__}")
        return {"result": codec.pack(result), "canceled": handle.is_cancel_requested}

    async def _cancel(self, req: dict[str, Any], stream: Any) -> bool:
        handle = self.goals.get(str(req.get("goal_id")))
        if handle is None:
            return False
        handle.request_cancel()
        return True

    def cancel_all(self) -> None:
        for handle in list(self.goals.values()):
            handle.request_cancel()

    async def start(self) -> None:
        await self.server.start()

    async def close(self) -> None:
        self.cancel_all()
        await self.server.close()


class ActionClient:
    """Blocking client: send a goal, get feedback through a callback, return the result."""

    def __init__(self, name: str, goal_type: Any, feedback_type: Any, result_type: Any, ctx: RunContext | None = None):
        self.name = name
        self.ctx = ctx or current()
        self.goal_type, self.feedback_type, self.result_type = resolve(goal_type), resolve(feedback_type), resolve(result_type)
        self.path = service_socket(self.ctx, name)

    def send_goal(self, goal: Any, feedback_callback: Callable[[Any], None] | None = None, timeout: float | None = None,
                  goal_id: str | None = None, wait_for_server: float = 0.0) -> Any:
        """Send ``goal`` and block until its result. ``wait_for_server``: seconds to keep trying
        while nothing serves the action yet (its component still starting, or restarting); the
        goal itself is sent once."""
        if not isinstance(goal, self.goal_type):
            raise TypeError(f"action {self.name!r} takes goals of {self.goal_type.__name__}, got {type(goal).__name__}")
        goal_id = goal_id or uuid.uuid4().hex

        def on_stream(frame: Any) -> None:
            if feedback_callback is not None and "feedback" in frame:
                feedback_callback(codec.decode(self.feedback_type, frame["feedback"], copy=True))

        with RpcClient(self.path, timeout=timeout or 3600.0) as rpc:
            reply = retry(lambda: rpc.call("goal", on_stream=on_stream, goal=codec.pack(goal), goal_id=goal_id),
                          attrs.evolve(UNREACHABLE_BACKOFF, timeout=max(0.0, wait_for_server)), retry_on=RpcUnreachable)
        result = codec.decode(self.result_type, reply["result"], copy=True)
        if reply.get("canceled"):
            raise ActionCanceled(f"action {self.name!r}: goal {goal_id} was canceled", result) from None
        return result

    def cancel(self, goal_id: str) -> bool:
        with RpcClient(self.path, timeout=5.0) as rpc:
            return bool(rpc.call("cancel", goal_id=goal_id))


# What each type of a service or an action is called, in order (ServiceServer, ActionServer).
SERVICE_ROLES = ("request", "response")
ACTION_ROLES = ("goal", "feedback", "result")


def describe_interfaces(declared: list[tuple[str, str, tuple[Any, ...]]], serving: set[str]) -> dict[str, list[dict[str, Any]]]:
    """The ``services`` and ``actions`` of a component's ``info`` answer, from its declared
    ``(kind, name, types)``: each with its name, whether it is served now (only while the
    component is active), and per role the type's canonical name and the module that defines it
    (so a client such as ``emos service call`` can load a type it has not imported yet)."""
    out: dict[str, list[dict[str, Any]]] = {"services": [], "actions": []}
    for kind, name, types in declared:
        entry: dict[str, Any] = {"name": name, "serving": name in serving}
        for role, given in zip(SERVICE_ROLES if kind == "service" else ACTION_ROLES, types):
            try:
                cls = resolve(given)
                entry[role] = {"type": canonical_name(cls), "module": cls.__module__}
            except UnknownMessageType:  # the server itself would refuse to start; say what was given
                entry[role] = {"type": str(given), "module": ""}
        out["services" if kind == "service" else "actions"].append(entry)
    return out


async def call_service_async(ctx: RunContext, name: str, request: Any, response_type: Any, timeout: float = 10.0,
                             wait_for_service: float = 0.0) -> Any:
    """Call service ``name`` of the run ``ctx``. ``wait_for_service``: seconds to keep trying while
    nothing serves it yet (its component still starting, or restarting); the request is sent once."""
    client = AsyncRpcClient(service_socket(ctx, name))
    try:
        raw = await retry_async(lambda: client.call("call", timeout=timeout, request=codec.pack(request)),
                                attrs.evolve(UNREACHABLE_BACKOFF, timeout=max(0.0, wait_for_service)), retry_on=RpcUnreachable)
        return codec.decode(resolve(response_type), raw, copy=True)
    finally:
        await client.close()
