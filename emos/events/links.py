"""Reaching components' control sockets for actions, across their deaths and restarts.

An action aimed at a component that is dead or restarting is not lost: the call is retried
(the action waits, queued, for the next incarnation) for up to ``queue_timeout`` seconds, and
then fails with an error naming the component, which the caller reports. A component that dies
*while* running an action gets it again from its next incarnation (at-least-once).
"""
from __future__ import annotations

import asyncio
import time
from typing import Any

from emos.core.node import control_socket
from emos.core.rpc import AsyncRpcClient, RpcConnectionError
from emos.events.action import ActionError
from emos.transport.context import RunContext


class ComponentLinks:
    def __init__(self, ctx: RunContext, queue_timeout: float = 10.0):
        self.ctx = ctx
        self.queue_timeout = queue_timeout
        self._clients: dict[str, AsyncRpcClient] = {}

    async def call(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        deadline = time.monotonic() + self.queue_timeout
        delay = 0.01
        while True:
            client = self._clients.get(component)
            if client is None:
                client = self._clients[component] = AsyncRpcClient(control_socket(self.ctx, component))
            try:
                return await client.call(op, timeout=timeout, **payload)
            except RpcConnectionError as exc:
                await client.close()
                if self._clients.get(component) is client:
                    del self._clients[component]
                if time.monotonic() >= deadline:
                    raise ActionError(f"component {component!r} unreachable for {self.queue_timeout:g} s ({exc}); {op} not delivered") from None
                await asyncio.sleep(delay)  # dead or restarting: wait for the next incarnation
                delay = min(delay * 2, 0.2)

    async def close(self) -> None:
        for client in self._clients.values():
            await client.close()
        self._clients.clear()
