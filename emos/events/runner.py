"""Running actions: one function for events (in the Monitor) and fallbacks (in the supervisor).

The two places differ only in how they reach things, which an :class:`ActionRuntime` provides:
a component's control socket, the supervisor's lifecycle operations, publishers, a thread pool
for recipe functions, and the latest message of each bound topic.
"""
from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from emos.core import control as C
from emos.events.action import Action, ActionError, resolve_bindings
from emos.io.topic import Topic
from emos.transport.context import RunContext


class ActionRuntime:
    """What running an action needs; the Monitor and the fallback driver each implement it."""

    ctx: RunContext
    log: logging.Logger
    timeout: float = 10.0  # seconds an action may take before it is reported as timed out

    async def call_component(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        raise NotImplementedError

    async def lifecycle(self, component: str, op: str, wait_time: float = 0.0) -> Any:
        raise NotImplementedError

    def publish(self, topic: Topic, msg: Any) -> None:
        raise NotImplementedError

    async def call_service(self, name: str, request: Any, response_type: type, component: str | None = None) -> Any:
        """Call service ``name`` of this run (``component``: the component offering it, if one
        does; a runtime that reaches other runs routes by it)."""
        from emos.core.services import call_service_async

        return await call_service_async(self.ctx, name, request, response_type, timeout=self.timeout, wait_for_service=self.timeout)

    async def send_goal(self, name: str, types: tuple[Any, Any, Any], goal: Any, component: str | None = None) -> Any:
        """Send ``goal`` to action server ``name`` of this run and return without waiting for its
        result (a goal may run for minutes); ``component`` as for :meth:`call_service`. A server
        that is not serving yet (an event can fire while its component still starts) is waited
        for up to :attr:`timeout` seconds."""
        from emos.core.services import ActionClient

        client = ActionClient(name, *types, ctx=self.ctx)
        await self.run_function(client.send_goal, (goal,), {"wait_for_server": self.timeout}, None)
        return True

    def latest(self, topic: str) -> Any | None:
        raise NotImplementedError

    async def run_function(self, fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any], timeout: float | None) -> Any:
        """Run a recipe function in a worker thread; ``timeout=None`` detaches it (fire and forget)."""
        loop = asyncio.get_running_loop()
        fut = loop.run_in_executor(None, lambda: fn(*args, **kwargs))
        if timeout is None:
            def report(f: asyncio.Future[Any]) -> None:
                if not f.cancelled() and f.exception() is not None:
                    self.log.error("background action %s failed: %s", getattr(fn, "__qualname__", fn), f.exception())

            fut.add_done_callback(report)
            return None
        return await asyncio.wait_for(asyncio.shield(fut), timeout)

    def periodic(self, key: str, period: float, duration: float | None, fn: Callable[[], Any]) -> None:
        """Call ``fn`` every ``period`` s for ``duration`` s (None: until stopped), replacing any
        earlier timer under the same ``key``."""
        tasks: dict[str, asyncio.Task[None]] = self.__dict__.setdefault("_periodic", {})
        old = tasks.pop(key, None)
        if old is not None:
            old.cancel()

        async def loop() -> None:
            end = None if duration is None else asyncio.get_running_loop().time() + duration
            while end is None or asyncio.get_running_loop().time() < end:
                try:
                    fn()
                except Exception as exc:
                    self.log.error("periodic action %s failed: %s", key, exc)
                await asyncio.sleep(period)

        tasks[key] = asyncio.ensure_future(loop())

    def cancel_periodic(self) -> None:
        for task in self.__dict__.get("_periodic", {}).values():
            task.cancel()


def prepare(action: Action, latest: Callable[[str], Any]) -> tuple[tuple[Any, ...], dict[str, Any]]:
    """Resolve the action's topic bindings now (at fire time), before it is queued."""
    return tuple(resolve_bindings(action.args, latest)), dict(resolve_bindings(action.kwargs, latest))


async def run_action(action: Action, rt: ActionRuntime, trigger_topic: str | None = None, trigger_msg: Any = None,
                     prepared: tuple[tuple[Any, ...], dict[str, Any]] | None = None) -> Any:
    """Run one action now; raises on failure (the caller reports it with its context)."""
    args, kwargs = prepared if prepared is not None else prepare(action, rt.latest)
    for parser, output in action.parsers:
        value = await rt.run_function(parser, (), {"msg": trigger_msg, "topic": trigger_topic}, rt.timeout)
        if output:
            kwargs[output] = value
        else:
            args = (value,) + tuple(args)
    kind = action.kind
    if kind == "component":
        assert action.component is not None
        where = f"action {action.describe()}"
        return await rt.call_component(action.component, C.EXECUTE_METHOD, rt.timeout, **C.method_request(action.method_name, args, kwargs, where))
    if kind == "lifecycle":
        return await rt.lifecycle(kwargs["component"], kwargs["op"], float(kwargs.get("wait_time") or 0.0))
    if kind == "step":
        assert action.component is not None
        return await rt.call_component(action.component, C.RUN_STEP, rt.timeout)
    if kind == "predefined":
        return await action.method(rt, trigger_topic=trigger_topic, trigger_msg=trigger_msg, **kwargs)
    if kind == "function":
        return await rt.run_function(action.method, tuple(args), kwargs, rt.timeout)
    raise ActionError(f"action {action.describe()}: unknown kind {kind!r}")


def step_action(component: Any) -> Action:
    """The action of a component whose trigger is an Event: run one step of it."""

    def run_step() -> None:  # never called directly: routed as a step request
        raise ActionError("step actions run inside their component")

    action = Action(run_step)
    action.kind = "step"
    action.component = component.component_name
    action.method_name = "step"
    return action
