"""Helpers shared by the server's route modules: JSON bodies, thread offloading, streaming."""
from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any, TypeVar

from aiohttp import web

from .limits import MAX_EMBED_CHARS, MAX_EMBED_INPUTS, MAX_JSON_DEPTH

T = TypeVar("T")
_END = object()


async def read_json(request: web.Request) -> Any:
    """The request body as JSON, or a ValueError saying why not (the routes answer it with 400)."""
    try:
        body = json.loads(await request.read() or b"null")
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"request body is not valid JSON ({exc})") from None
    except RecursionError:  # e.g. 100,000 nested '[': the decoder recurses per level
        raise ValueError(f"request body is nested too deeply (more than {MAX_JSON_DEPTH} levels)") from None
    if json_depth(body) > MAX_JSON_DEPTH:  # parsed, but the codecs and json.dumps recurse too
        raise ValueError(f"request body is nested too deeply (more than {MAX_JSON_DEPTH} levels)")
    return body


def json_depth(value: Any) -> int:
    """Nesting depth of a decoded JSON value (a scalar is 0), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            item = list(item.values())
        if isinstance(item, list):
            depth += 1
            deepest = max(deepest, depth)
            stack.extend((child, depth) for child in item if isinstance(child, (dict, list)))
    return deepest


def model_name(body: Any, *keys: str) -> str | None:
    """The model a request names under the first of ``keys`` present: a string, or None if absent."""
    if not isinstance(body, dict):
        raise ValueError("body: expected a JSON object")
    for key in keys:
        name = body.get(key)
        if name is None:
            continue
        if not isinstance(name, str):
            raise ValueError(f"{key!r} must be a string, got {type(name).__name__}")
        return name
    return None


def text_inputs(body: Any) -> list[str]:
    """The ``input`` of an embeddings request (OpenAI and Ollama share the shape): one or more
    strings, at most ``MAX_EMBED_INPUTS`` of them and ``MAX_EMBED_CHARS`` characters together."""
    if not isinstance(body, dict) or "input" not in body:
        raise ValueError("body: expected a JSON object with an 'input'")
    texts = body["input"]
    texts = [texts] if isinstance(texts, str) else texts
    if not isinstance(texts, list) or not texts or not all(isinstance(t, str) for t in texts):
        raise ValueError("'input' must be a string or a non-empty list of strings")
    if len(texts) > MAX_EMBED_INPUTS:
        raise ValueError(f"'input' has {len(texts)} texts; at most {MAX_EMBED_INPUTS} per request")
    total = sum(len(t) for t in texts)
    if total > MAX_EMBED_CHARS:
        raise ValueError(f"'input' has {total} characters in all; at most {MAX_EMBED_CHARS} per request")
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
