"""RoboML inference payloads <-> EMOS types (shared by the HTTP, WebSocket and RESP clients).

RoboML's input models: chat ``{"query": [{role, content}...], "images": [base64...],
"stream", "temperature", "max_new_tokens"}``; TTS ``{"query": text, "voice", "get_bytes"}``;
STT ``{"query": base64 audio}``; detection ``{"images", "threshold", "labels_to_track"}``.
Every reply is ``{"output": ...}``.
"""
from __future__ import annotations

import base64
import json
from typing import Any

import msgpack

from ..errors import ErrorContext, MalformedResponseError, ModelClientError
from ..types import (
    ChatMessage,
    ChatRequest,
    ChatResponse,
    Detection2D,
    DetectionRequest,
    DetectionResponse,
    SpeechRequest,
    SpeechResponse,
    TranscriptionRequest,
    TranscriptionResponse,
)

__all__ = ["MODEL_KINDS", "kind_of", "build_payload", "parse_output"]

MODEL_KINDS = {
    "TransformersLLM": "chat",
    "TransformersMLLM": "chat",
    "RoboBrain2": "chat",
    "Whisper": "stt",
    "SpeechT5": "tts",
    "Bark": "tts",
    "MeloTTS": "tts",
    "VisionModel": "detect",
}
REQUEST_KINDS = {ChatRequest: "chat", SpeechRequest: "tts", TranscriptionRequest: "stt", DetectionRequest: "detect"}


def kind_of(request: Any, model_type: str, ctx: ErrorContext) -> str:
    kind = REQUEST_KINDS.get(type(request))
    if kind is None:
        raise TypeError(f"RoboML clients take ChatRequest, SpeechRequest, TranscriptionRequest or DetectionRequest, got {type(request).__name__}")
    if MODEL_KINDS[model_type] != kind:
        raise TypeError(f"a {model_type} model cannot answer a {type(request).__name__}")
    if kind == "chat" and request.tools:
        raise ModelClientError("RoboML models do not support tool calling; use GenericHTTPClient or OllamaClient", **ctx)
    return kind


def build_payload(request: Any, kind: str, *, raw_bytes: bool = False) -> dict[str, Any]:
    """The inference input dict. ``raw_bytes`` sends audio as bytes (msgpack transports)."""
    if kind == "chat":
        messages = [{"role": m.role, "content": m.content or ""} for m in request.messages]
        images = [img.to_base64() for m in request.messages for img in m.images]
        payload: dict[str, Any] = {
            "query": messages,
            "stream": request.stream,
            "temperature": 0.7 if request.temperature is None else request.temperature,
            "max_new_tokens": 100 if request.max_tokens is None else request.max_tokens,
        }
        if images:
            payload["images"] = images
        if request.task:  # RoboML's PlanningInput (RoboBrain 2.0): the model answers in the task's structure
            payload["task"] = request.task
        return payload
    if kind == "tts":
        payload = {"query": request.text, "get_bytes": raw_bytes}
        if request.voice:
            payload["voice"] = request.voice
        return payload
    if kind == "stt":
        return {"query": request.audio if raw_bytes else base64.b64encode(request.audio).decode()}
    payload = {"images": [img.to_base64() for img in request.images], "threshold": request.threshold}
    if request.labels_to_track:
        payload["labels_to_track"] = list(request.labels_to_track)
    return payload


def parse_output(body: Any, kind: str, model: str, ctx: ErrorContext) -> Any:
    """Decode ``{"output": ...}`` into the response type matching ``kind``."""
    if not isinstance(body, dict) or "output" not in body:
        raise MalformedResponseError("a RoboML result object with 'output'", body, **ctx)
    return parse_value(body["output"], kind, model, ctx)


def parse_value(output: Any, kind: str, model: str, ctx: ErrorContext) -> Any:
    if kind == "chat":
        if isinstance(output, bytes):  # a structured planning answer over msgpack (WebSocket)
            try:
                output = msgpack.unpackb(output, raw=False)
            except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
                raise MalformedResponseError("text or a structured planning answer", output[:60], **ctx) from None
        if isinstance(output, list):
            # Planning models (RoboBrain 2.0 on RoboML) answer a task with its structure, e.g.
            # grounding boxes [[x1, y1, x2, y2], ...]; as JSON text the VLM's task parser reads it.
            output = json.dumps(output)
        if not isinstance(output, str):
            raise MalformedResponseError("text output", output, **ctx)
        return ChatResponse(message=ChatMessage(role="assistant", content=output), finish_reason="stop", model=model)
    if kind == "stt":
        if not isinstance(output, str):
            raise MalformedResponseError("transcribed text", output, **ctx)
        return TranscriptionResponse(text=output)
    if kind == "tts":
        if isinstance(output, str):
            try:
                output = base64.b64decode(output, validate=True)
            except ValueError:
                raise MalformedResponseError("base64 audio", output[:60], **ctx) from None
        if not isinstance(output, bytes) or not output:
            raise MalformedResponseError("audio bytes", output, **ctx)
        mime = "audio/wav" if output[:4] == b"RIFF" else "application/octet-stream"
        return SpeechResponse(audio=output, mime_type=mime)
    if not isinstance(output, list):
        raise MalformedResponseError("a list of per-image detections", output, **ctx)
    try:
        return DetectionResponse([Detection2D(boxes=d["bboxes"], labels=d["labels"], scores=d["scores"]) for d in output])
    except (KeyError, TypeError, ValueError):
        raise MalformedResponseError("detections with bboxes, labels and scores", output, **ctx) from None
