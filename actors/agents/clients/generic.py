"""GenericHTTPClient: any OpenAI-compatible server (vLLM, LMDeploy, OpenAI, ``emos serve models``)."""
from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

from ..errors import MalformedResponseError, ModelNotFoundError
from ..models import GenericSTT, GenericTTS
from ..types import (
    AUDIO_MIME,
    ChatChunk,
    ChatRequest,
    ChatResponse,
    EmbeddingRequest,
    EmbeddingResponse,
    SpeechRequest,
    SpeechResponse,
    TranscriptionRequest,
    TranscriptionResponse,
)
from . import openai_codec
from .base import ModelClient
from .http_transport import HTTPTransport
from .sse import iter_sse_data

__all__ = ["GenericHTTPClient"]


class GenericHTTPClient(ModelClient):
    """OpenAI-compatible HTTP client: chat (streamed or not, tools, images), embeddings, speech
    and transcription. The API key comes from ``api_key`` or the ``OPENAI_API_KEY`` variable."""

    SUPPORTED_MODELS = ("GenericLLM", "GenericMLLM", "GenericTTS", "GenericSTT", "TransformersLLM", "TransformersMLLM")

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 8000, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", api_key: str | None = None,
                 **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        if api_key is not None and not isinstance(api_key, str):
            raise TypeError(f"GenericHTTPClient.api_key: expected a string, got {type(api_key).__name__}")
        # Only an explicitly given key is serialized; the environment is read in each process.
        self._explicit_api_key = api_key
        self.api_key = api_key or os.environ.get("OPENAI_API_KEY")
        headers = {"Authorization": f"Bearer {self.api_key}"} if self.api_key else {}
        self._http = HTTPTransport(self.url, timeout=self.inference_timeout, connect_timeout=self.connect_timeout,
                                   headers=headers, context=self._error_context())

    def _extra_serialized(self) -> dict[str, Any]:
        return {"api_key": self._explicit_api_key}

    @property
    def checkpoint(self) -> str:
        return self.model.checkpoint

    def _defaults(self) -> dict[str, Any]:
        return dict(getattr(self.model, "options", None) or {})

    # ------------------------------------------------------------------ lifecycle
    def _check_connection(self) -> None:
        self._list_models()

    def _list_models(self) -> list[str]:
        body = self._http.request_json("GET", "/v1/models")
        data = body.get("data") if isinstance(body, dict) else None
        if not isinstance(data, list):
            raise MalformedResponseError("a model list object with 'data'", body, **self._http.context_for("/v1/models"))
        return [str(item.get("id")) for item in data if isinstance(item, dict)]

    def _initialize(self) -> None:
        # OpenAI-compatible servers load models themselves; we only verify the checkpoint is served.
        served = self._list_models()
        if served and self.checkpoint not in served:
            raise ModelNotFoundError(
                f"checkpoint {self.checkpoint!r} is not served; available: {served[:20]}",
                **self._http.context_for("/v1/models"),
            )

    def close(self) -> None:
        self._http.close()

    # ------------------------------------------------------------------ inference
    def _chat(self, request: ChatRequest) -> ChatResponse:
        payload = openai_codec.build_chat_payload(request, self.checkpoint, self._defaults())
        body = self._http.request_json("POST", "/v1/chat/completions", json=payload)
        return openai_codec.parse_chat_response(body, self._http.context_for("/v1/chat/completions"))

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        payload = openai_codec.build_chat_payload(request, self.checkpoint, self._defaults())
        lines = self._http.stream_lines("POST", "/v1/chat/completions", json=payload)
        return openai_codec.parse_chat_stream(iter_sse_data(lines), self._http.context_for("/v1/chat/completions"))

    def _embed(self, request: EmbeddingRequest) -> EmbeddingResponse:
        path = "/v1/embeddings"
        body = self._http.request_json("POST", path, json={"model": self.checkpoint, "input": request.texts})
        try:
            rows = sorted(body["data"], key=lambda d: d.get("index", 0))
            vectors = [row["embedding"] for row in rows]
            response = EmbeddingResponse(embeddings=vectors, model=body.get("model", ""), usage=body.get("usage"))
        except (KeyError, TypeError, ValueError):
            raise MalformedResponseError("an embedding list object", body, **self._http.context_for(path)) from None
        if response.embeddings.shape[0] != len(request.texts):
            raise MalformedResponseError(f"{len(request.texts)} embeddings", f"{response.embeddings.shape[0]}", **self._http.context_for(path))
        return response

    def _speech(self, request: SpeechRequest) -> SpeechResponse:
        voice = request.voice or (self.model.voice if isinstance(self.model, GenericTTS) else "alloy")
        speed = request.speed or (self.model.speed if isinstance(self.model, GenericTTS) else 1.0)
        payload = {"model": self.checkpoint, "input": request.text, "voice": voice, "speed": speed,
                   "response_format": request.response_format}
        response = self._http.request("POST", "/v1/audio/speech", json=payload)
        if not response.content:
            raise MalformedResponseError("audio bytes", "an empty body", **self._http.context_for("/v1/audio/speech"))
        mime = response.headers.get("content-type", AUDIO_MIME[request.response_format]).split(";")[0]
        return SpeechResponse(audio=response.content, mime_type=mime)

    def _transcribe(self, request: TranscriptionRequest) -> TranscriptionResponse:
        path = "/v1/audio/transcriptions"
        data: dict[str, Any] = {"model": self.checkpoint, "response_format": "json"}
        language = request.language or (self.model.language if isinstance(self.model, GenericSTT) else None)
        temperature = request.temperature if request.temperature is not None else getattr(self.model, "temperature", None)
        if language:
            data["language"] = language
        if temperature is not None:
            data["temperature"] = str(temperature)
        if request.prompt:
            data["prompt"] = request.prompt
        files = {"file": (request.filename, request.audio, "application/octet-stream")}
        body = self._http.request_json("POST", path, data=data, files=files)
        if not isinstance(body, dict) or not isinstance(body.get("text"), str):
            raise MalformedResponseError("a transcription object with 'text'", body, **self._http.context_for(path))
        return TranscriptionResponse(text=body["text"], language=body.get("language"))
