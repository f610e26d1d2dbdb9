"""Helpers shared by the server's route modules: JSON bodies, thread offloading, streaming."""
from __future__ import annotations

import asyncio
import json
from typing import Any, AsyncIterator, Callable, Iterator, TypeVar

from aiohttp import web

T = TypeVar("T")
_END = object()


async def read_json(request: web.Request) -> Any:
    """The request body as JSON, or a ValueError saying why not."""
    try:
        return json.loads(await request.read() or b"null")
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"request body is not valid JSON ({exc})") from None


def text_inputs(body: Any) -> list[str]:
    """The ``input`` of an embeddings request (OpenAI and Ollama share the shape): one or more strings."""
    texts = body["input"]
    texts = [texts] if isinstance(texts, str) else texts
    if not isinstance(texts, list) or not texts or not all(isinstance(t, str) for t in texts):
        raise ValueError("'input' must be a string or a non-empty list of strings")
    return texts


async def in_thread(fn: Callable[..., T], *args: Any) -> T:
    """Run a blocking model call off the event loop."""
    return await asyncio.get_running_loop().run_in_executor(None, fn, *args)


async def iterate_in_thread(gen: Iterator[T]) -> AsyncIterator[T]:
    """Drive a blocking generator from the event loop, one item per worker-thread hop."""
    loop = asyncio.get_running_loop()
    while True:
        item = await loop.run_in_executor(None, next, gen, _END)
        if item is _END:
            return
        yield item  # type: ignore[misc]
