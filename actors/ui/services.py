"""Service calls from the page: ``launcher.enable_ui(inputs=[ServiceClientConfig(...)])``.

A service shows on the page as a form of its request's fields (the card actions use, so the page
needs nothing new): Send calls the service once and the card shows the response, or why the
call failed. A response with ``success=False`` counts as failed (the service said no).
:class:`InputRunners` puts the action runner and the service runner behind the one interface the
server uses (``describe``, ``send``, ``cancel``, ``close``).
"""
from __future__ import annotations

import asyncio
import logging
import uuid
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from emos.actors.ui.actions import ActionRunner
from emos.actors.ui.codecs import summarize
from emos.actors.ui.inputs import InputRefused, goal_from_page
from emos.actors.ui.widgets import describe_fields
from emos.core.rpc import AsyncRpcClient, RpcConnectionError, RpcError
from emos.core.service_config import ServiceClientConfig
from emos.msgs import codec

log = logging.getLogger("emos.ui")

Reply = Callable[[dict[str, Any]], Awaitable[None]]


def service_key(name: str) -> str:
    """Services are keyed as their component names them (``planner/save_plan_to_file``)."""
    return name.strip("/")


class ServiceRunner:
    def __init__(self, services: dict[str, ServiceClientConfig], socket_of: Callable[[str], Path]):
        self.services = {service_key(k): v for k, v in services.items()}
        self.socket_of = socket_of
        self._calls: set[asyncio.Future[None]] = set()  # held until done (the loop keeps weak references)

    def describe(self) -> list[dict[str, Any]]:
        return [{"topic": name, "type": s.request_type.__name__, "kind": "action", "service": True,
                 "component": name.split("/", 1)[0], "click": False, "fields": describe_fields(s.request_type)}
                for name, s in self.services.items()]

    def owns(self, name: Any) -> bool:
        return isinstance(name, str) and service_key(name) in self.services

    def send(self, req: dict[str, Any], reply: Reply) -> dict[str, Any]:
        """Call the service; its response (or the failure) goes to ``reply`` when it comes."""
        name, rid = service_key(str(req.get("topic"))), req.get("id")
        service = self.services.get(name)
        if service is None:
            return {"op": "result", "id": rid, "ok": False, "error": f"{name!r} is not a service of this page"}
        try:
            request = goal_from_page(name, service.request_type, req.get("value"))
        except InputRefused as exc:
            return {"op": "result", "id": rid, "ok": False, "error": str(exc)}
        call_id = uuid.uuid4().hex
        task = asyncio.ensure_future(self._call(name, service, request, call_id, reply))
        self._calls.add(task)
        task.add_done_callback(self._calls.discard)
        return {"op": "result", "id": rid, "ok": True, "goal_id": call_id}

    async def _call(self, name: str, service: ServiceClientConfig, request: Any, call_id: str, send: Reply) -> None:
        async def reply(state: str, value: Any) -> None:
            try:
                await send({"op": "action", "topic": name, "goal_id": call_id, "state": state, "value": value})
            except (ConnectionError, RuntimeError):
                pass  # the page went away; the call's outcome has nobody to go to

        await reply("sent", summarize(request))
        state, value = await self.call_once(name, service, request)
        await reply("failed" if state == "unreachable" else state, value)

    async def call_once(self, name: str, service: ServiceClientConfig, request: Any) -> tuple[str, Any]:
        """Call ``service`` with ``request``: ("succeeded" | "failed" | "unreachable", the response's
        summary or why). A response with ``success=False`` counts as failed (the service said no)."""
        client = AsyncRpcClient(self.socket_of(service.name))
        try:
            raw = await client.call("call", timeout=service.timeout_secs, request=codec.pack(request))
            response = codec.decode(service.response_type, raw, copy=True)
        except (RpcConnectionError, OSError, TimeoutError) as exc:
            log.warning("[ui] call to service %s failed: %s", name, exc)
            return "unreachable", str(exc)
        except (RpcError, ValueError) as exc:
            log.warning("[ui] call to service %s failed: %s", name, exc)
            return "failed", str(exc)
        finally:
            await client.close()
        refused = getattr(response, "success", True) is False
        return ("failed" if refused else "succeeded"), summarize(response)

    def cancel(self, req: dict[str, Any]) -> dict[str, Any]:
        return {"op": "result", "id": req.get("id"), "ok": False,
                "error": f"{service_key(str(req.get('topic')))} is a service: a call cannot be canceled"}

    def close(self) -> None:
        for task in list(self._calls):
            task.cancel()


class InputRunners:
    """The page's actions and services behind one interface (a service name wins over an action's)."""

    def __init__(self, actions: ActionRunner, services: ServiceRunner):
        self.actions, self.services = actions, services

    def describe(self) -> list[dict[str, Any]]:
        return self.actions.describe() + self.services.describe()

    def send(self, req: dict[str, Any], reply: Reply) -> dict[str, Any]:
        runner: Any = self.services if self.services.owns(req.get("topic")) else self.actions
        return runner.send(req, reply)

    def cancel(self, req: dict[str, Any]) -> dict[str, Any]:
        runner: Any = self.services if self.services.owns(req.get("topic")) else self.actions
        return runner.cancel(req)

    def close(self) -> None:
        self.actions.close()
        self.services.close()


def with_services(actions: ActionRunner, services: dict[str, ServiceClientConfig] | None, socket_of: Callable[[str], Path]) -> Any:
    """The runner the server uses: ``actions`` alone, or with the page's services."""
    if not services:
        return actions
    return InputRunners(actions, ServiceRunner(services, socket_of))
