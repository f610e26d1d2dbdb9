"""Goals from the page to a component's action server, with feedback and result sent back."""
from __future__ import annotations

import asyncio
import logging
import uuid
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from emos.actors.ui.codecs import summarize
from emos.actors.ui.inputs import InputRefused, goal_field, goal_from_page
from emos.actors.ui.widgets import describe_fields
from emos.core.action_input import ActionInput
from emos.core.rpc import AsyncRpcClient, RpcConnectionError, RpcError
from emos.msgs import codec

log = logging.getLogger("emos.ui")


class ActionRunner:
    def __init__(self, actions: dict[str, ActionInput], socket_of: Callable[[str], Path]):
        self.actions, self.socket_of = actions, socket_of
        self._running: dict[str, tuple[str, asyncio.Task]] = {}  # action -> (goal id, task)
        # Fire-and-forget sends and cancels: the loop keeps only weak references to tasks, so
        # they are held here until done (else one could be collected half-way).
        self._background: set[asyncio.Future[None]] = set()

    def _spawn(self, coro: Awaitable[None]) -> None:
        task = asyncio.ensure_future(coro)
        self._background.add(task)
        task.add_done_callback(self._background.discard)

    def describe(self) -> list[dict[str, Any]]:
        out = []
        for a in self.actions.values():
            out.append({"topic": a.name, "type": a.goal_type.__name__, "kind": "action", "component": a.component,
                        "click": goal_field(a.goal_type) is not None, "fields": describe_fields(a.goal_type)})
        return out

    def send(self, req: dict[str, Any], reply: Callable[[dict[str, Any]], Awaitable[None]]) -> dict[str, Any]:
        """Start a goal; feedback and the result go to ``reply`` as they come."""
        name, rid = str(req.get("topic")), req.get("id")
        action = self.actions.get(name)
        if action is None:
            return {"op": "result", "id": rid, "ok": False, "error": f"{name!r} is not an action of this page"}
        try:
            goal = goal_from_page(name, action.goal_type, req.get("value"))
        except InputRefused as exc:
            return {"op": "result", "id": rid, "ok": False, "error": str(exc)}
        previous = self._running.get(name)
        if previous is not None and not previous[1].done():
            self._spawn(self._cancel(action, previous[0]))  # a new goal replaces the running one
        goal_id = uuid.uuid4().hex
        task = asyncio.ensure_future(self._run(action, goal, goal_id, reply))
        self._running[name] = (goal_id, task)
        return {"op": "result", "id": rid, "ok": True, "goal_id": goal_id}

    async def _run(self, action: ActionInput, goal: Any, goal_id: str, send: Callable[[dict[str, Any]], Awaitable[None]]) -> None:
        async def reply(message: dict[str, Any]) -> None:
            try:
                await send(message)
            except (ConnectionError, RuntimeError):
                pass  # the page went away; the goal goes on, its outcome has nobody to go to

        def on_stream(frame: Any) -> None:
            if isinstance(frame, dict) and "feedback" in frame:
                feedback = codec.decode(action.feedback_type, frame["feedback"], copy=True)
                self._spawn(reply({"op": "action", "topic": action.name, "goal_id": goal_id, "state": "feedback",
                                   "value": summarize(feedback)}))

        client = AsyncRpcClient(self.socket_of(action.name))
        await reply({"op": "action", "topic": action.name, "goal_id": goal_id, "state": "sent", "value": summarize(goal)})
        try:
            answer = await client.call("goal", timeout=None, on_stream=on_stream, goal=codec.pack(goal), goal_id=goal_id)
            result = codec.decode(action.result_type, answer["result"], copy=True)
            state = "canceled" if answer.get("canceled") else "succeeded"
            await reply({"op": "action", "topic": action.name, "goal_id": goal_id, "state": state, "value": summarize(result)})
        except (RpcError, RpcConnectionError, OSError) as exc:
            log.warning("[ui] goal to %s failed: %s", action.name, exc)
            await reply({"op": "action", "topic": action.name, "goal_id": goal_id, "state": "failed", "value": str(exc)})
        finally:
            await client.close()

    async def _cancel(self, action: ActionInput, goal_id: str) -> None:
        client = AsyncRpcClient(self.socket_of(action.name))
        try:
            await client.call("cancel", timeout=5.0, goal_id=goal_id)
        except Exception as exc:
            log.warning("[ui] cancelling the goal on %s failed: %s", action.name, exc)
        finally:
            await client.close()

    def cancel(self, req: dict[str, Any]) -> dict[str, Any]:
        name, rid = str(req.get("topic")), req.get("id")
        running = self._running.get(name)
        if running is None or running[1].done():
            return {"op": "result", "id": rid, "ok": False, "error": f"no goal running on {name}"}
        self._spawn(self._cancel(self.actions[name], running[0]))
        return {"op": "result", "id": rid, "ok": True}

    def close(self) -> None:
        for _, task in self._running.values():
            task.cancel()
