"""llama.cpp chat backend: a real LLM from a GGUF file, for the model server and in-process.

Needs ``llama-cpp-python`` (the ``local-llm`` extra; it compiles llama.cpp). The import is lazy
so nothing loads it unless a local model is asked for. ``emos serve models --local-llm`` serves
the packaged SmolLM2-135M-Instruct with it; ``--gguf FILE`` any GGUF chat model; the LLM/VLM
components run it in their own process (``enable_local_model=True``, see local_client.py).

The models this is used with are text-only: a request that carries images is answered from
its text, with each image replaced by a note saying that it cannot be seen, so the model says
so rather than invent a scene (and nothing crashes on an image part the template cannot hold).

Threads on a shared, busy computer: llama.cpp here is built with OpenMP (libgomp), and its
threads meet at an OpenMP barrier after every operation of the graph, hundreds per token.
libgomp's default is to spin at a barrier; when more threads want the CPUs than there are,
a spinning thread burns the time slice the thread it waits for needs. Measured on 2 cores at
load 7-21: 16 tokens with 2 threads took 24-45 s spinning and 1.3-3.1 s with waiting threads
asleep (``OMP_WAIT_POLICY=PASSIVE``), against 1.1-1.9 s with one thread. So the process sets
``OMP_WAIT_POLICY=PASSIVE`` before llama.cpp is loaded, unless the environment sets it.

Tools and chat templates: llama.cpp formats a chat with the template stored in the GGUF file,
and a template without a tools section (SmolLM2's has none) silently drops the ``tools`` of a
request: the model was asked to call tools it was never shown (Cortex with SmolLM2: 154 prompt
tokens, none of them a tool). For such a template the tools are written into the system message
as JSON lines, with the instruction to answer a call as ``{"name": ..., "arguments": {...}}``
(the form Cortex and the tool loop read from text), and earlier tool calls of the assistant are
written as that JSON in its message, so the template has text to render.
"""
from __future__ import annotations

import json
import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import GenerationAbandoned
from ..types import ChatChunk, ChatMessage, ChatRequest, ChatResponse, ToolCall, ToolSpec, decode_tool_arguments
from .gguf import EXTRA_HINT, SMOLLM2_FILE, SMOLLM2_NAMES, LocalModelError, LocalModelUnavailable, check_gguf

__all__ = ["LlamaCppResponder", "IMAGE_NOTE", "default_threads"]

IMAGE_NOTE = "[An image was attached here, but this model is text-only and cannot see it.]"


def _import_llama() -> Any:
    """``llama_cpp.Llama``, with OpenMP threads that sleep at barriers (see the module docstring).
    libgomp reads the variable when it is loaded, i.e. at the first import of llama_cpp."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    from llama_cpp import Llama

    return Llama


def default_threads() -> int:
    """llama.cpp threads by default: one. With sleeping OpenMP threads (above) every barrier of
    a multi-threaded graph costs a futex wake, hundreds per token; one thread has no barriers.
    SmolLM2 on this machine's 2 cores, in-process decode: idle, 1 thread 72 tokens/s against 2
    threads 39-53; beside two CPU hogs 35 steady against 25-57. Spinning threads (a bounded
    GOMP_SPINCOUNT) reach 110-117 idle but fall to 0.5-4.4 beside the hogs: on a robot computer
    shared with other components that is the case to design for. Ask for more threads with
    ``ncpu_local_model`` / ``--threads`` for a bigger model on a dedicated computer."""
    return 1


TOOLS_NOTE = ("You can call these tools. To call one, answer with a JSON object "
              '{"name": "<tool>", "arguments": {...}} for each call, one per line. The tools:')


def tools_as_text(tools: list[ToolSpec]) -> str:
    """The tools of a request, written for a model whose chat template cannot show them."""
    lines = [json.dumps({"name": t.name, "description": t.description, "parameters": t.parameters}, sort_keys=True)
             for t in tools]
    return "\n".join([TOOLS_NOTE, *lines])


def _call_text(message: ChatMessage) -> str:
    """The assistant's tool calls as the JSON text a template without tools can render."""
    calls = "\n".join(json.dumps({"name": c.name, "arguments": c.arguments}) for c in message.tool_calls)
    return f"{message.content}\n{calls}" if message.content else calls


def _message(message: ChatMessage, native_tools: bool = True) -> dict[str, Any]:
    """One message in llama-cpp-python's OpenAI shape, text only (see the module docstring)."""
    content = message.content
    if message.images:
        notes = " ".join([IMAGE_NOTE] * len(message.images))
        content = f"{notes}\n{content}" if content else notes
    if message.tool_calls and not native_tools:
        content = _call_text(message)
    out: dict[str, Any] = {"role": message.role, "content": content if content is not None else ""}
    if message.tool_calls and native_tools:
        out["tool_calls"] = [{"id": c.id, "type": "function",
                              "function": {"name": c.name, "arguments": json.dumps(c.arguments)}}
                             for c in message.tool_calls]
    if message.tool_call_id is not None:
        out["tool_call_id"] = message.tool_call_id
    if message.name is not None:
        out["name"] = message.name
    return out


class LlamaCppResponder:
    """Chat through ``llama_cpp.Llama.create_chat_completion`` (OpenAI-shaped in and out).

    ``name`` is the file's stem; ``aliases`` are further names it answers to on the server (the
    packaged SmolLM2 also answers to "smollm2", "smollm2:135m" and its Hugging Face name)."""

    def __init__(self, gguf_path: str | os.PathLike[str], n_ctx: int = 4096, n_threads: int | None = None,
                 seed: int | None = None) -> None:
        path = check_gguf(gguf_path)
        try:
            Llama = _import_llama()
        except ImportError as exc:
            raise LocalModelUnavailable(f"the GGUF model {str(path)!r} needs llama-cpp-python: {EXTRA_HINT}") from exc
        self.path = path
        self.name = path.stem
        self.aliases: tuple[str, ...] = tuple(n for n in SMOLLM2_NAMES if n != self.name) if path.name == SMOLLM2_FILE else ()
        self.n_threads = n_threads or default_threads()
        kwargs: dict[str, Any] = {"model_path": str(path), "n_ctx": n_ctx, "n_threads": self.n_threads,
                                  "n_threads_batch": self.n_threads, "verbose": False}
        if seed is not None:
            kwargs["seed"] = seed
        try:
            self._llm: Any = Llama(**kwargs)  # None once closed
        except (ValueError, RuntimeError, OSError) as exc:
            # A file with a valid header but broken tensors, or an architecture llama.cpp lacks.
            raise LocalModelError(f"llama.cpp could not load the GGUF model {str(path)!r}: {exc}") from None
        # llama.cpp contexts are not thread-safe; requests are served one at a time.
        self._lock = threading.Lock()
        # cancel(): the generation in progress ends at its next token (see _kwargs' logits processor).
        self._cancel = threading.Event()
        self._busy = False
        #: tokens sampled in the generation in progress (or the last one)
        self.tokens_generated = 0
        #: tokens sampled after the last cancel() in the generation it cancelled (1: the end token)
        self.tokens_after_cancel = 0
        template = (getattr(self._llm, "metadata", None) or {}).get("tokenizer.chat_template") or ""
        #: whether the model's chat template renders a request's tools (see the module docstring)
        self.native_tools = "tools" in template

    @property
    def context_size(self) -> int:
        return int(self._llm.n_ctx())

    def _kwargs(self, request: ChatRequest) -> dict[str, Any]:
        messages = [_message(m, self.native_tools) for m in request.messages]
        if request.tools and self.native_tools:
            kwargs: dict[str, Any] = {"messages": messages, "tools": [t.to_openai() for t in request.tools]}
        elif request.tools:
            note = tools_as_text(list(request.tools))
            if messages and messages[0]["role"] == "system":
                messages[0] = {**messages[0], "content": f"{messages[0]['content']}\n\n{note}"}
            else:
                messages.insert(0, {"role": "system", "content": note})
            kwargs = {"messages": messages}
        else:
            kwargs = {"messages": messages}
        if request.temperature is not None:
            kwargs["temperature"] = request.temperature
        if request.max_tokens is not None:
            kwargs["max_tokens"] = request.max_tokens
        seed = request.options.get("seed")
        if isinstance(seed, int) and not isinstance(seed, bool):
            kwargs["seed"] = seed
        kwargs["logits_processor"] = [self._watch_cancel]
        return kwargs

    def _watch_cancel(self, input_ids: Any, scores: Any) -> Any:
        """Called by llama.cpp before each token is sampled: once cancel() was called, only the
        end-of-generation token may follow, so the generation stops at this token (create_chat_
        completion has no other way to stop, and no abort of a running decode)."""
        self.tokens_generated += 1
        if self._cancel.is_set():
            self.tokens_after_cancel += 1
            eos = self._llm.token_eos()
            scores[:] = -float("inf")
            scores[eos] = 0.0
        return scores

    def cancel(self) -> bool:
        """Abandon the generation in progress, without waiting for it: it ends at its next token
        and its caller gets :class:`GenerationAbandoned`. False if none is in progress."""
        if not self._busy:
            return False
        self._cancel.set()
        return True

    def _begin(self) -> None:  # under self._lock
        self._cancel.clear()
        self._busy = True
        self.tokens_generated = self.tokens_after_cancel = 0

    def _abandoned(self) -> GenerationAbandoned:
        return GenerationAbandoned(f"local model {self.name!r}: the answer in progress was abandoned after "
                                   f"{self.tokens_generated} token(s): the component switched to another model client")

    def respond(self, request: ChatRequest, model: str) -> ChatResponse:
        with self._lock:
            self._begin()
            try:
                # llama-cpp-python's TypedDicts: read as plain JSON, as the OpenAI codec reads a server's.
                out: Any = self._llm.create_chat_completion(**self._kwargs(request))
            finally:
                self._busy = False
            if self._cancel.is_set():
                raise self._abandoned()  # a truncated answer is not published as the answer
        choice = out["choices"][0]
        raw = choice["message"]
        calls = [ToolCall(id=c.get("id", ""), name=c["function"]["name"], arguments=decode_tool_arguments(c["function"].get("arguments")))
                 for c in raw.get("tool_calls") or []]
        message = ChatMessage(role="assistant", content=raw.get("content"), tool_calls=calls)
        return ChatResponse(message=message, finish_reason=choice.get("finish_reason"), usage=out.get("usage"), model=model)

    def stream(self, request: ChatRequest, model: str) -> Iterator[ChatChunk]:
        # The lock is held while the generator runs; closing the generator early (a client
        # that went away) leaves the ``with`` and releases it.
        with self._lock:
            reason = None
            tokens = 0
            self._begin()
            try:
                parts: Any = self._llm.create_chat_completion(stream=True, **self._kwargs(request))
                for part in parts:
                    if self._cancel.is_set():
                        parts.close()
                        raise self._abandoned()
                    choice = part["choices"][0]
                    text = (choice.get("delta") or {}).get("content")
                    if text:
                        tokens += 1  # llama-cpp-python streams one token per chunk
                        yield ChatChunk(content=text)
                    reason = choice.get("finish_reason") or reason
            finally:
                self._busy = False
            if self._cancel.is_set():
                raise self._abandoned()
        yield ChatChunk(content="", done=True, finish_reason=reason or "stop", usage={"completion_tokens": tokens})

    def close(self) -> None:
        llm = getattr(self, "_llm", None)
        if llm is not None:
            with self._lock:
                llm.close()
                self._llm = None

    @staticmethod
    def resolve(path: str | os.PathLike[str] | None) -> Path:
        """The GGUF file a responder for ``path`` would open (None: the packaged SmolLM2)."""
        from .gguf import resolve_gguf

        return resolve_gguf(path)
