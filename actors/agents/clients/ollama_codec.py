"""Ollama ``/api/chat`` wire format <-> EMOS types, both directions, as pure functions.

Reference: https://github.com/ollama/ollama/blob/main/docs/api.md ("Generate a chat
completion": request, streamed NDJSON objects ending with ``"done": true``, tool calls whose
``arguments`` is a JSON object; images are plain base64 strings without a data-URL prefix).
"""
from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from datetime import UTC, datetime
from typing import Any

from ..errors import ErrorContext, MalformedResponseError
from ..types import ChatChunk, ChatMessage, ChatRequest, ChatResponse, ImageData, ToolCall, ToolSpec, decode_tool_arguments

__all__ = [
    "message_to_ollama",
    "build_chat_payload",
    "parse_chat_response",
    "parse_chat_stream",
    "chat_request_from_ollama",
    "chat_message_to_ollama",
    "ollama_timestamp",
]

Context = ErrorContext


def message_to_ollama(message: ChatMessage) -> dict[str, Any]:
    out: dict[str, Any] = {"role": message.role, "content": message.content or ""}
    if message.images:
        out["images"] = [img.to_base64() for img in message.images]
    if message.tool_calls:
        out["tool_calls"] = [{"function": {"name": c.name, "arguments": c.arguments}} for c in message.tool_calls]
    if message.role == "tool" and message.name:
        out["tool_name"] = message.name
    return out


def build_chat_payload(request: ChatRequest, model: str, defaults: dict[str, Any] | None = None,
                       keep_alive: Any = None) -> dict[str, Any]:
    """Body of ``POST /api/chat``. Component temperature/max_tokens override model options."""
    options: dict[str, Any] = dict(defaults or {})
    options.update({k: v for k, v in request.options.items() if k != "think"})
    if request.temperature is not None:
        options["temperature"] = request.temperature
    if request.max_tokens is not None:
        options["num_predict"] = request.max_tokens
    think = options.pop("think", request.options.get("think"))
    payload: dict[str, Any] = {
        "model": model,
        "messages": [message_to_ollama(m) for m in request.messages],
        "stream": request.stream,
    }
    if options:
        payload["options"] = options
    if think is not None:
        payload["think"] = think  # a top-level field in the API, not an option
    if request.tools:
        payload["tools"] = [t.to_openai() for t in request.tools]
    if keep_alive is not None:
        payload["keep_alive"] = keep_alive
    return payload


def _message(raw: Any, ctx: Context) -> tuple[str, list[ToolCall]]:
    if not isinstance(raw, dict):
        raise MalformedResponseError("an object with a 'message' object", raw, **ctx)
    content = raw.get("content")
    if content is not None and not isinstance(content, str):
        raise MalformedResponseError("message.content as a string", content, **ctx)
    calls = []
    for i, item in enumerate(raw.get("tool_calls") or []):
        fn = item.get("function") if isinstance(item, dict) else None
        if not isinstance(fn, dict) or not fn.get("name"):
            raise MalformedResponseError("a tool call with function.name", item, **ctx)
        calls.append(ToolCall(id=item.get("id") or f"call_{i}", name=fn["name"], arguments=decode_tool_arguments(fn.get("arguments"), **ctx)))
    return content or "", calls


def _usage(body: dict[str, Any]) -> dict[str, Any] | None:
    if "prompt_eval_count" not in body and "eval_count" not in body:
        return None
    prompt, completion = body.get("prompt_eval_count", 0), body.get("eval_count", 0)
    return {"prompt_tokens": prompt, "completion_tokens": completion, "total_tokens": prompt + completion}


def parse_chat_response(body: Any, ctx: Context) -> ChatResponse:
    if not isinstance(body, dict) or "message" not in body:
        raise MalformedResponseError("an /api/chat object with 'message'", body, **ctx)
    content, calls = _message(body["message"], ctx)
    return ChatResponse(
        message=ChatMessage(role="assistant", content=content, tool_calls=calls),
        finish_reason="tool_calls" if calls else body.get("done_reason", "stop"),
        usage=_usage(body),
        model=body.get("model", ""),
    )


def parse_chat_stream(objects: Iterable[dict[str, Any]], ctx: Context) -> Iterator[ChatChunk]:
    """NDJSON objects -> chunks; the final ``done`` chunk carries the collected tool calls."""
    calls: list[ToolCall] = []
    for obj in objects:
        if "error" in obj:
            raise MalformedResponseError("a chat chunk, not an in-stream error", obj["error"], **ctx)
        content, new_calls = _message(obj.get("message", {}), ctx)
        calls.extend(new_calls)
        if content:
            yield ChatChunk(content=content)
        if obj.get("done"):
            reason = "tool_calls" if calls else obj.get("done_reason", "stop")
            yield ChatChunk(content="", tool_calls=calls, done=True, finish_reason=reason, usage=_usage(obj))
            return
    raise MalformedResponseError("an NDJSON stream ending with a 'done': true object", "end of stream", **ctx)


# ------------------------------------------------------------------ server side


def chat_request_from_ollama(body: dict[str, Any]) -> tuple[str, ChatRequest]:
    if not isinstance(body, dict) or not isinstance(body.get("messages"), list):
        raise ValueError("body: expected a JSON object with a 'messages' list")
    messages = []
    for raw in body["messages"]:
        calls = [ToolCall(id=f"call_{i}", name=c["function"]["name"], arguments=decode_tool_arguments(c["function"].get("arguments")))
                 for i, c in enumerate(raw.get("tool_calls") or [])]
        messages.append(ChatMessage(
            role=raw.get("role", ""), content=raw.get("content"),
            images=[ImageData.from_base64(b) for b in raw.get("images") or []],
            tool_calls=calls, name=raw.get("tool_name"),
        ))
    options = dict(body.get("options") or {})
    tools = [ToolSpec(name=t["function"]["name"], description=t["function"].get("description", ""),
                      parameters=t["function"].get("parameters") or {"type": "object", "properties": {}})
             for t in body.get("tools") or []]
    request = ChatRequest(
        messages=messages, tools=tools, stream=bool(body.get("stream", True)),
        temperature=options.pop("temperature", None), max_tokens=options.pop("num_predict", None), options=options,
    )
    return str(body.get("model", "")), request


def ollama_timestamp() -> str:
    return datetime.now(UTC).isoformat().replace("+00:00", "Z")


def chat_message_to_ollama(model: str, content: str, tool_calls: list[ToolCall], done: bool,
                           done_reason: str | None = None, started: float | None = None,
                           prompt_tokens: int = 0, completion_tokens: int = 0) -> dict[str, Any]:
    message: dict[str, Any] = {"role": "assistant", "content": content}
    if tool_calls:
        message["tool_calls"] = [{"function": {"name": c.name, "arguments": c.arguments}} for c in tool_calls]
    out: dict[str, Any] = {"model": model, "created_at": ollama_timestamp(), "message": message, "done": done}
    if done:
        total = int((time.monotonic() - (started or time.monotonic())) * 1e9)
        out.update({"done_reason": done_reason or "stop", "total_duration": total, "load_duration": 0,
                    "prompt_eval_count": prompt_tokens, "eval_count": completion_tokens})
    return out
