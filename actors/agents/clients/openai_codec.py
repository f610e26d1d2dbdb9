"""OpenAI chat-completions wire format <-> EMOS types, both directions, as pure functions.

Clients use the ``build_*`` / ``parse_*`` pair; the local model server uses the reverse pair,
so one module owns the format. Reference: https://platform.openai.com/docs/api-reference/chat
(request, response object and streamed chunk object).
"""
from __future__ import annotations

import json
import time
import uuid
from collections.abc import Iterable, Iterator
from typing import Any

from ..errors import ErrorContext, MalformedResponseError
from ..types import (
    ChatChunk,
    ChatMessage,
    ChatRequest,
    ChatResponse,
    ImageData,
    ToolCall,
    ToolSpec,
    decode_tool_arguments,
)
from .sse import SSE_DONE

__all__ = [
    "message_to_openai",
    "build_chat_payload",
    "parse_chat_response",
    "parse_chat_stream",
    "chat_request_from_openai",
    "chat_response_to_openai",
    "chunk_to_openai",
    "completion_id",
]

Context = ErrorContext


# ------------------------------------------------------------------ client side: requests


def message_to_openai(message: ChatMessage) -> dict[str, Any]:
    out: dict[str, Any] = {"role": message.role}
    if message.images:
        parts: list[dict[str, Any]] = []
        if message.content:
            parts.append({"type": "text", "text": message.content})
        parts.extend({"type": "image_url", "image_url": {"url": img.to_data_url()}} for img in message.images)
        out["content"] = parts
    else:
        out["content"] = message.content
    if message.tool_calls:
        out["tool_calls"] = [
            {
                "id": call.id,
                "type": "function",
                # OpenAI expects arguments as a JSON *string* on the way in, too.
                "function": {"name": call.name, "arguments": json.dumps(call.arguments)},
            }
            for call in message.tool_calls
        ]
    if message.tool_call_id is not None:
        out["tool_call_id"] = message.tool_call_id
    if message.name is not None:
        out["name"] = message.name
    return out


def build_chat_payload(request: ChatRequest, model: str, defaults: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON body of ``POST /v1/chat/completions``; request fields override model defaults."""
    payload: dict[str, Any] = dict(defaults or {})
    payload.update(request.options)
    payload["model"] = model
    payload["messages"] = [message_to_openai(m) for m in request.messages]
    if request.temperature is not None:
        payload["temperature"] = request.temperature
    if request.max_tokens is not None:
        payload["max_tokens"] = request.max_tokens
    if request.tools:
        payload["tools"] = [t.to_openai() for t in request.tools]
    payload["stream"] = request.stream
    if request.stream:
        payload["stream_options"] = {"include_usage": True}
    return payload


# ------------------------------------------------------------------ client side: responses


def _tool_calls_from_openai(raw: Any, ctx: Context) -> list[ToolCall]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise MalformedResponseError("message.tool_calls as a list", raw, **ctx)
    calls = []
    for item in raw:
        fn = item.get("function") if isinstance(item, dict) else None
        if not isinstance(fn, dict) or not fn.get("name"):
            raise MalformedResponseError("a tool call with function.name", item, **ctx)
        calls.append(ToolCall(id=item.get("id") or "", name=fn["name"], arguments=decode_tool_arguments(fn.get("arguments"), **ctx)))
    return calls


def parse_chat_response(body: Any, ctx: Context) -> ChatResponse:
    """Decode a non-streamed chat completion object."""
    try:
        choice = body["choices"][0]
        raw_message = choice["message"]
    except (KeyError, IndexError, TypeError):
        raise MalformedResponseError("a chat.completion object with choices[0].message", body, **ctx) from None
    if not isinstance(raw_message, dict):
        raise MalformedResponseError("choices[0].message as an object", raw_message, **ctx)
    content = raw_message.get("content")
    if content is not None and not isinstance(content, str):
        raise MalformedResponseError("message.content as a string or null", content, **ctx)
    message = ChatMessage(
        role="assistant",
        content=content,
        tool_calls=_tool_calls_from_openai(raw_message.get("tool_calls"), ctx),
    )
    return ChatResponse(message=message, finish_reason=choice.get("finish_reason"), usage=body.get("usage"), model=body.get("model", ""))


class _ToolCallAssembler:
    """Joins streamed tool-call fragments by ``index``; arguments arrive as partial JSON text."""

    def __init__(self) -> None:
        self.parts: dict[int, dict[str, str]] = {}

    def add(self, fragments: Any, ctx: Context) -> None:
        if not isinstance(fragments, list):
            raise MalformedResponseError("delta.tool_calls as a list", fragments, **ctx)
        for frag in fragments:
            if not isinstance(frag, dict):
                raise MalformedResponseError("a tool-call fragment object", frag, **ctx)
            index = frag.get("index", len(self.parts))
            slot = self.parts.setdefault(index, {"id": "", "name": "", "arguments": ""})
            slot["id"] = frag.get("id") or slot["id"]
            fn = frag.get("function") or {}
            slot["name"] += fn.get("name") or ""
            args = fn.get("arguments")
            if isinstance(args, dict):  # some servers send the whole object at once
                args = json.dumps(args)
            slot["arguments"] += args or ""

    def finish(self, ctx: Context) -> list[ToolCall]:
        calls = []
        for index in sorted(self.parts):
            slot = self.parts[index]
            if not slot["name"]:
                raise MalformedResponseError("a streamed tool call with a function name", slot, **ctx)
            calls.append(ToolCall(id=slot["id"], name=slot["name"], arguments=decode_tool_arguments(slot["arguments"], **ctx)))
        return calls


def parse_chat_stream(events: Iterable[str], ctx: Context) -> Iterator[ChatChunk]:
    """Turn SSE data payloads into chunks; the last chunk has ``done=True`` and the tool calls.

    A ``null`` content delta is an empty string (the original broke on it). A stream that ends
    with neither ``[DONE]`` nor a ``finish_reason`` was cut off: that is a malformed response.
    """
    tools = _ToolCallAssembler()
    finish_reason: str | None = None
    usage: dict | None = None
    done = False
    for data in events:
        if data.strip() == SSE_DONE:
            done = True
            break
        try:
            obj = json.loads(data)
        except ValueError:
            raise MalformedResponseError("an SSE data line holding a JSON chunk", data, **ctx) from None
        if not isinstance(obj, dict):
            raise MalformedResponseError("a chat.completion.chunk object", data, **ctx)
        if "error" in obj:
            raise MalformedResponseError("a chat.completion.chunk, not an in-stream error", obj["error"], **ctx)
        if obj.get("usage"):
            usage = obj["usage"]
        choices = obj.get("choices")
        if not isinstance(choices, list):
            raise MalformedResponseError("chunk.choices as a list", obj, **ctx)
        for choice in choices:
            delta = choice.get("delta") or {}
            if delta.get("tool_calls"):
                tools.add(delta["tool_calls"], ctx)
            content = delta.get("content")
            if content:
                yield ChatChunk(content=content)
            if choice.get("finish_reason"):
                finish_reason = choice["finish_reason"]
    if not done and finish_reason is None:
        raise MalformedResponseError("a stream ending with 'data: [DONE]'", "end of stream", **ctx)
    yield ChatChunk(content="", tool_calls=tools.finish(ctx), done=True, finish_reason=finish_reason, usage=usage)


# ------------------------------------------------------------------ server side


def _message_from_openai(raw: Any) -> ChatMessage:
    if not isinstance(raw, dict):
        raise ValueError(f"messages: expected objects, got {raw!r}")
    content = raw.get("content")
    images: list[ImageData] = []
    if isinstance(content, list):
        texts = []
        for part in content:
            kind = part.get("type") if isinstance(part, dict) else None
            if kind == "text":
                texts.append(part.get("text", ""))
            elif kind == "image_url":
                url = part.get("image_url")
                url = url.get("url") if isinstance(url, dict) else url
                images.append(ImageData.from_base64(url or ""))
            else:
                raise ValueError(f"messages[].content: unsupported part {part!r}")
        content = "\n".join(texts) if texts else None
    calls = []
    for item in raw.get("tool_calls") or []:
        fn = item.get("function", {})
        calls.append(ToolCall(id=item.get("id", ""), name=fn.get("name", ""), arguments=decode_tool_arguments(fn.get("arguments"))))
    return ChatMessage(
        role=raw.get("role", ""), content=content, images=images, tool_calls=calls,
        tool_call_id=raw.get("tool_call_id"), name=raw.get("name"),
    )


def chat_request_from_openai(body: dict[str, Any]) -> tuple[str, ChatRequest]:
    """(model name, request) from a ``/v1/chat/completions`` body. Raises ValueError if invalid."""
    if not isinstance(body, dict) or not isinstance(body.get("messages"), list):
        raise ValueError("body: expected a JSON object with a 'messages' list")
    tools = [ToolSpec(name=t["function"]["name"], description=t["function"].get("description", ""),
                      parameters=t["function"].get("parameters") or {"type": "object", "properties": {}})
             for t in body.get("tools") or []]
    known = {"model", "messages", "tools", "stream", "temperature", "max_tokens", "stream_options", "tool_choice"}
    request = ChatRequest(
        messages=[_message_from_openai(m) for m in body["messages"]],
        tools=tools,
        stream=bool(body.get("stream", False)),
        temperature=body.get("temperature"),
        max_tokens=body.get("max_tokens") or body.get("max_completion_tokens"),
        options={k: v for k, v in body.items() if k not in known},
    )
    return str(body.get("model", "")), request


def completion_id() -> str:
    return f"chatcmpl-{uuid.uuid4().hex[:24]}"


def chat_response_to_openai(response: ChatResponse, response_id: str | None = None) -> dict[str, Any]:
    message: dict[str, Any] = {"role": "assistant", "content": response.message.content}
    if response.message.tool_calls:
        message["tool_calls"] = [
            {"id": c.id, "type": "function", "function": {"name": c.name, "arguments": json.dumps(c.arguments)}}
            for c in response.message.tool_calls
        ]
    return {
        "id": response_id or completion_id(),
        "object": "chat.completion",
        "created": int(time.time()),
        "model": response.model,
        "choices": [{"index": 0, "message": message, "logprobs": None, "finish_reason": response.finish_reason}],
        "usage": response.usage,
    }


def chunk_to_openai(completion_id: str, model: str, delta: dict[str, Any], finish_reason: str | None = None,
                    usage: dict | None = None, created: int | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "id": completion_id,
        "object": "chat.completion.chunk",
        "created": created or int(time.time()),
        "model": model,
        "choices": [{"index": 0, "delta": delta, "logprobs": None, "finish_reason": finish_reason}],
    }
    if usage is not None:
        out["usage"] = usage
    return out
