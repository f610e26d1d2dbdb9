"""Ollama-compatible endpoints: /api/chat (NDJSON), /api/generate, /api/tags, /api/show,
/api/pull, /api/embed, /api/version."""
from __future__ import annotations

import json
import time
from typing import Any

from aiohttp import web

from ..clients import ollama_codec
from ..types import ChatMessage, ChatRequest
from .backends import EMBEDDING_NAMES, BackendUnavailable, LocalModels
from .common import in_thread, iterate_in_thread, model_name, read_json, text_inputs
from .guard import takes_json

__all__ = ["add_ollama_routes"]


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


def _ndjson(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj).encode() + b"\n"


def add_ollama_routes(app: web.Application, models: LocalModels) -> None:
    def details(name: str) -> dict[str, Any]:
        family = "bert" if name in EMBEDDING_NAMES else "emos"
        return {"format": "gguf" if family != "emos" else "scripted", "family": family, "families": [family],
                "parameter_size": "0", "quantization_level": "none"}

    async def tags(_request: web.Request) -> web.Response:
        now = ollama_codec.ollama_timestamp()
        entries = [{"name": n, "model": n, "modified_at": now, "size": 0, "digest": "", "details": details(n)}
                   for n in models.all_names()]
        return web.json_response({"models": entries})

    async def version(_request: web.Request) -> web.Response:
        return web.json_response({"version": "0.0.0-emos"})

    @takes_json
    async def show(request: web.Request) -> web.Response:
        try:
            body = await read_json(request)
            name = model_name(body, "model", "name")
        except ValueError as exc:
            return _error(400, str(exc))
        if not name or not models.has(name):
            return _error(404, f"model '{name}' not found")
        caps = ["embedding"] if name in EMBEDDING_NAMES else ["completion", "tools"]
        return web.json_response({"modelfile": f"# served by emos serve models\nFROM {name}\n", "parameters": "",
                                  "template": "", "details": details(name), "model_info": {}, "capabilities": caps})

    @takes_json
    async def pull(request: web.Request) -> web.StreamResponse:
        # Nothing is downloaded: models are local. Success for models we have, an error otherwise.
        try:
            body = await read_json(request)
            name = model_name(body, "model", "name")
        except ValueError as exc:
            return _error(400, str(exc))
        if not name or not models.has(name):
            return _error(404, f"pull model manifest: model '{name}' is not available on this local server (no downloads)")
        if body.get("stream", True) is False:
            return web.json_response({"status": "success"})
        stream = web.StreamResponse(headers={"Content-Type": "application/x-ndjson"})
        await stream.prepare(request)
        for status in ("pulling manifest", "verifying sha256 digest", "writing manifest", "success"):
            await stream.write(_ndjson({"status": status}))
        await stream.write_eof()
        return stream

    @takes_json
    async def chat(request: web.Request) -> web.StreamResponse:
        body: Any = None
        try:
            body = await read_json(request)
            model_name(body, "model")
            model, chat_request = ollama_codec.chat_request_from_ollama(body)
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            # Ollama allows an empty message list to load/unload a model; so do we.
            if isinstance(body, dict) and body.get("messages") == [] and isinstance(body.get("model"), str) \
                    and body["model"]:
                return await load_only(body)
            return _error(400, f"invalid chat request: {exc}")
        backend = models.chat_backend(model)
        if backend is None:
            return _error(404, f"model '{model}' not found")
        model = model or models.default_chat
        started = time.monotonic()
        if not chat_request.stream:
            response = await in_thread(backend.respond, chat_request, model)
            usage = response.usage or {}
            return web.json_response(ollama_codec.chat_message_to_ollama(
                model, response.message.content or "", response.message.tool_calls, True, response.finish_reason,
                started, usage.get("prompt_tokens", 0), usage.get("completion_tokens", 0)))
        stream = web.StreamResponse(headers={"Content-Type": "application/x-ndjson"})
        await stream.prepare(request)
        async for piece in iterate_in_thread(backend.stream(chat_request, model)):
            if piece.done:
                if piece.tool_calls:  # Ollama sends tool calls in a non-final message
                    await stream.write(_ndjson(ollama_codec.chat_message_to_ollama(model, "", piece.tool_calls, False)))
                usage = piece.usage or {}
                reason = "stop" if piece.finish_reason in (None, "tool_calls") else piece.finish_reason
                await stream.write(_ndjson(ollama_codec.chat_message_to_ollama(
                    model, "", [], True, reason, started, usage.get("prompt_tokens", 0), usage.get("completion_tokens", 0))))
            elif piece.content:
                await stream.write(_ndjson(ollama_codec.chat_message_to_ollama(model, piece.content, [], False)))
        await stream.write_eof()
        return stream

    async def load_only(body: dict[str, Any]) -> web.Response:
        name = body.get("model")
        if not models.has(name):
            return _error(404, f"model '{name}' not found")
        reason = "unload" if body.get("keep_alive") in (0, "0", "0s") else "load"
        return web.json_response({"model": name, "created_at": ollama_codec.ollama_timestamp(),
                                  "message": {"role": "assistant", "content": ""}, "done_reason": reason, "done": True})

    @takes_json
    async def generate(request: web.Request) -> web.StreamResponse:
        try:
            body = await read_json(request)
            name = model_name(body, "model") or models.default_chat
        except ValueError as exc:
            return _error(400, str(exc))
        prompt = body.get("prompt")
        if not prompt:  # empty prompt = load (or, with keep_alive 0, unload) the model
            if not models.has(name):
                return _error(404, f"model '{name}' not found")
            reason = "unload" if body.get("keep_alive") in (0, "0", "0s") else "load"
            return web.json_response({"model": name, "created_at": ollama_codec.ollama_timestamp(), "response": "",
                                      "done": True, "done_reason": reason})
        backend = models.chat_backend(name)
        if backend is None:
            return _error(404, f"model '{name}' not found")
        messages = [ChatMessage(role="user", content=str(prompt))]
        if body.get("system"):
            messages.insert(0, ChatMessage(role="system", content=str(body["system"])))
        chat_request = ChatRequest(messages=messages, stream=bool(body.get("stream", True)))
        started = time.monotonic()
        if not chat_request.stream:
            response = await in_thread(backend.respond, chat_request, name)
            return web.json_response({"model": name, "created_at": ollama_codec.ollama_timestamp(),
                                      "response": response.message.content or "", "done": True, "done_reason": "stop",
                                      "total_duration": int((time.monotonic() - started) * 1e9)})
        stream = web.StreamResponse(headers={"Content-Type": "application/x-ndjson"})
        await stream.prepare(request)
        async for piece in iterate_in_thread(backend.stream(chat_request, name)):
            out = {"model": name, "created_at": ollama_codec.ollama_timestamp(), "response": piece.content, "done": piece.done}
            if piece.done:
                out["done_reason"] = piece.finish_reason or "stop"
            await stream.write(_ndjson(out))
        await stream.write_eof()
        return stream

    @takes_json
    async def embed(request: web.Request) -> web.Response:
        try:
            body = await read_json(request)
            texts = text_inputs(body)
            name = model_name(body, "model")
        except (ValueError, TypeError, KeyError) as exc:
            return _error(400, f"invalid embed request: {exc}")
        if name not in EMBEDDING_NAMES:
            return _error(404, f"model '{name}' not found")
        started = time.monotonic()
        try:
            vectors = await in_thread(models.embed, texts)
        except BackendUnavailable as exc:
            return _error(501, str(exc))
        return web.json_response({"model": name, "embeddings": vectors.tolist(),
                                  "total_duration": int((time.monotonic() - started) * 1e9), "load_duration": 0,
                                  "prompt_eval_count": sum(len(t.split()) for t in texts)})

    app.router.add_get("/api/tags", tags)
    app.router.add_get("/api/version", version)
    app.router.add_post("/api/show", show)
    app.router.add_post("/api/pull", pull)
    app.router.add_post("/api/chat", chat)
    app.router.add_post("/api/generate", generate)
    app.router.add_post("/api/embed", embed)
