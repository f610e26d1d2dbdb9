"""Optional llama.cpp chat backend for the local model server (a real LLM from a GGUF file).

Needs ``llama-cpp-python`` (not installed by default: it compiles llama.cpp). The import is
lazy so the server starts without it unless ``--gguf`` is given.
"""
from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..clients.openai_codec import message_to_openai
from ..types import ChatChunk, ChatMessage, ChatRequest, ChatResponse, ToolCall, decode_tool_arguments

__all__ = ["LlamaCppResponder"]


class LlamaCppResponder:
    """Chat through ``llama_cpp.Llama.create_chat_completion`` (OpenAI-shaped in and out)."""

    def __init__(self, gguf_path: str, n_ctx: int = 4096, n_threads: int | None = None) -> None:
        path = Path(gguf_path)
        if not path.is_file():
            raise FileNotFoundError(f"--gguf: file {gguf_path!r} does not exist")
        try:
            from llama_cpp import Llama
        except ImportError as exc:
            raise ImportError(
                "--gguf needs llama-cpp-python: pip install llama-cpp-python "
                "(it builds llama.cpp; CPU build is fine)"
            ) from exc
        self.name = path.stem
        self._llm = Llama(model_path=str(path), n_ctx=n_ctx, n_threads=n_threads, verbose=False)
        # llama.cpp contexts are not thread-safe; requests are served one at a time.
        self._lock = threading.Lock()

    def _kwargs(self, request: ChatRequest) -> dict[str, Any]:
        kwargs: dict[str, Any] = {"messages": [message_to_openai(m) for m in request.messages]}
        if request.tools:
            kwargs["tools"] = [t.to_openai() for t in request.tools]
        if request.temperature is not None:
            kwargs["temperature"] = request.temperature
        if request.max_tokens is not None:
            kwargs["max_tokens"] = request.max_tokens
        return kwargs

    def respond(self, request: ChatRequest, model: str) -> ChatResponse:
        with self._lock:
            out = self._llm.create_chat_completion(**self._kwargs(request))
        choice = out["choices"][0]
        raw = choice["message"]
        calls = [ToolCall(id=c.get("id", ""), name=c["function"]["name"], arguments=decode_tool_arguments(c["function"].get("arguments")))
                 for c in raw.get("tool_calls") or []]
        message = ChatMessage(role="assistant", content=raw.get("content"), tool_calls=calls)
        return ChatResponse(message=message, finish_reason=choice.get("finish_reason"), usage=out.get("usage"), model=model)

    def stream(self, request: ChatRequest, model: str) -> Iterator[ChatChunk]:
        with self._lock:
            reason = None
            for part in self._llm.create_chat_completion(stream=True, **self._kwargs(request)):
                choice = part["choices"][0]
                text = (choice.get("delta") or {}).get("content")
                if text:
                    yield ChatChunk(content=text)
                reason = choice.get("finish_reason") or reason
        yield ChatChunk(content="", done=True, finish_reason=reason or "stop")
