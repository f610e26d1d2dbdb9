"""OpenAI-compatible endpoints: /v1/models, /v1/chat/completions (SSE), /v1/embeddings,
/v1/audio/speech, /v1/audio/transcriptions."""
from __future__ import annotations

import json
import time

from aiohttp import web

from ..clients import openai_codec
from ..clients.sse import SSE_DONE, format_sse
from ..types import AUDIO_MIME
from .backends import EMBEDDING_NAMES, BackendUnavailable, LocalModels
from .common import in_thread, iterate_in_thread, model_name, read_json, text_inputs
from .guard import takes_json

__all__ = ["add_openai_routes"]


def _error(status: int, message: str, kind: str = "invalid_request_error") -> web.Response:
    body = {"error": {"message": message, "type": kind, "param": None, "code": None}}
    return web.json_response(body, status=status)


def add_openai_routes(app: web.Application, models: LocalModels) -> None:
    async def list_models(_request: web.Request) -> web.Response:
        created = int(time.time())
        data = [{"id": name, "object": "model", "created": created, "owned_by": "emos"} for name in models.all_names()]
        return web.json_response({"object": "list", "data": data})

    @takes_json
    async def chat(request: web.Request) -> web.StreamResponse:
        try:
            body = await read_json(request)
            model_name(body, "model")
            model, chat_request = openai_codec.chat_request_from_openai(body)
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            return _error(400, f"invalid chat request: {exc}")
        backend = models.chat_backend(model)
        if backend is None:
            return _error(404, f"The model '{model}' does not exist", "not_found_error")
        model = model or models.default_chat
        if not chat_request.stream:
            response = await in_thread(backend.respond, chat_request, model)
            return web.json_response(openai_codec.chat_response_to_openai(response))
        stream = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"})
        await stream.prepare(request)
        cid, created = openai_codec.completion_id(), int(time.time())

        async def send(delta: dict, finish: str | None = None, usage: dict | None = None) -> None:
            chunk = openai_codec.chunk_to_openai(cid, model, delta, finish, usage, created)
            await stream.write(format_sse(json.dumps(chunk)))

        await send({"role": "assistant", "content": ""})
        async for piece in iterate_in_thread(backend.stream(chat_request, model)):
            if piece.content:
                await send({"content": piece.content})
            if piece.done:
                for index, call in enumerate(piece.tool_calls):
                    # Real servers split arguments across chunks; so do we, to exercise clients.
                    args = json.dumps(call.arguments)
                    cut = len(args) // 2
                    await send({"tool_calls": [{"index": index, "id": call.id, "type": "function",
                                                "function": {"name": call.name, "arguments": args[:cut]}}]})
                    await send({"tool_calls": [{"index": index, "function": {"arguments": args[cut:]}}]})
                await send({}, piece.finish_reason or "stop")
                if piece.usage:
                    usage = openai_codec.chunk_to_openai(cid, model, {}, None, piece.usage, created)
                    usage["choices"] = []
                    await stream.write(format_sse(json.dumps(usage)))
        await stream.write(format_sse(SSE_DONE))
        await stream.write_eof()
        return stream

    @takes_json
    async def embeddings(request: web.Request) -> web.Response:
        try:
            body = await read_json(request)
            texts = text_inputs(body)
            model = model_name(body, "model") or EMBEDDING_NAMES[0]
        except (ValueError, TypeError, KeyError) as exc:
            return _error(400, f"invalid embeddings request: {exc}")
        if model not in EMBEDDING_NAMES:
            return _error(404, f"The model '{model}' does not exist", "not_found_error")
        try:
            vectors = await in_thread(models.embed, texts)
        except BackendUnavailable as exc:
            return _error(501, str(exc), "server_error")
        data = [{"object": "embedding", "index": i, "embedding": v.tolist()} for i, v in enumerate(vectors)]
        tokens = sum(len(t.split()) for t in texts)
        return web.json_response({"object": "list", "data": data, "model": model,
                                  "usage": {"prompt_tokens": tokens, "total_tokens": tokens}})

    @takes_json
    async def speech(request: web.Request) -> web.Response:
        try:
            body = await read_json(request)
            if not isinstance(body, dict):
                raise ValueError("body: expected a JSON object")
            text = body["input"]
            if not isinstance(text, str) or not text.strip():
                raise ValueError("'input' must be a non-empty string")
            speed = float(body.get("speed", 1.0))
            if not 0.25 <= speed <= 4.0:
                raise ValueError("'speed' must be within 0.25..4.0")
            voice = body.get("voice")
            if voice is not None and not isinstance(voice, str):
                raise ValueError("'voice' must be a string")
        except (ValueError, TypeError, KeyError) as exc:
            return _error(400, f"invalid speech request: {exc}")
        fmt = body.get("response_format", "wav")
        if fmt != "wav":
            return _error(400, f"response_format {str(fmt)[:40]!r} is not supported by the local server; use 'wav'")
        try:
            audio = await in_thread(models.synthesize, text, voice, speed)
        except BackendUnavailable as exc:
            return _error(501, str(exc), "server_error")
        except RuntimeError as exc:
            return _error(400, f"speech synthesis failed: {exc}")
        return web.Response(body=audio, content_type=AUDIO_MIME["wav"])

    async def transcriptions(request: web.Request) -> web.Response:
        if not request.content_type.startswith("multipart/"):
            return _error(400, "expected a multipart/form-data body with a 'file' part")
        try:
            form = await request.post()
        except ValueError as exc:  # a malformed multipart body
            return _error(400, f"the multipart/form-data body could not be read: {exc}")
        upload = form.get("file")
        if upload is None or not hasattr(upload, "file"):
            return _error(400, "missing the 'file' part")
        audio = upload.file.read()
        language = form.get("language") or None
        if language is not None and not isinstance(language, str):
            return _error(400, "'language' must be a text field")
        try:
            text = await in_thread(models.transcribe, audio, language)
        except BackendUnavailable as exc:
            return _error(501, str(exc), "server_error")
        except ValueError as exc:
            return _error(400, str(exc))
        return web.json_response({"text": text})

    app.router.add_get("/v1/models", list_models)
    app.router.add_post("/v1/chat/completions", chat)
    app.router.add_post("/v1/embeddings", embeddings)
    app.router.add_post("/v1/audio/speech", speech)
    app.router.add_post("/v1/audio/transcriptions", transcriptions)
