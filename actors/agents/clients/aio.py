"""Async facade over any model client, for components that run on an asyncio (uvloop) loop.

The clients are synchronous (httpx, websockets.sync, sockets, grpc); this wrapper runs each
call in a worker thread so the event loop never blocks on a model. Streams are drained one
chunk per thread hop, so an ``async for`` sees chunks as soon as the server sends them.
"""
from __future__ import annotations

import asyncio
import enum
from collections.abc import AsyncIterator, Iterator
from typing import Any

from ..types import ChatChunk
from .base import ModelClient

__all__ = ["AsyncClient"]


class _End(enum.Enum):
    """The end-of-stream sentinel (an enum member, so that ``is _END`` narrows its type)."""

    END = enum.auto()


_END = _End.END


class AsyncClient:
    """``await client.inference(request)``; streamed chat returns an async iterator of chunks."""

    def __init__(self, client: ModelClient) -> None:
        if not isinstance(client, ModelClient):
            raise TypeError(f"AsyncClient: expected a ModelClient, got {type(client).__name__}")
        self.client = client

    async def check_connection(self) -> None:
        await asyncio.to_thread(self.client.check_connection)

    async def initialize(self) -> None:
        await asyncio.to_thread(self.client.initialize)

    async def deinitialize(self) -> None:
        await asyncio.to_thread(self.client.deinitialize)

    async def inference(self, request: Any) -> Any:
        result = await asyncio.to_thread(self.client.inference, request)
        if isinstance(result, Iterator):
            return self._drain(result)
        return result

    @staticmethod
    async def _drain(chunks: Iterator[ChatChunk]) -> AsyncIterator[ChatChunk]:
        while True:
            chunk = await asyncio.to_thread(next, chunks, _END)
            if chunk is _END:
                return
            yield chunk

    def __getattr__(self, name: str) -> Any:  # model_name, inference_timeout, serialize, ...
        return getattr(self.client, name)
