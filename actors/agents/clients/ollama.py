"""OllamaClient: chat (NDJSON streaming, images, tools, options), embeddings, pull/show,
keep_alive preload and unload, over Ollama's HTTP API."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from ..errors import MalformedResponseError, ModelNotFoundError, ModelServerError
from ..models.ollama import OllamaModel
from ..types import ChatChunk, ChatRequest, ChatResponse, EmbeddingRequest, EmbeddingResponse
from . import ollama_codec
from .base import ModelClient
from .http_transport import HTTPTransport

__all__ = ["OllamaClient"]


class OllamaClient(ModelClient):
    """Client for an Ollama server (default port 11434)."""

    SUPPORTED_MODELS = ("OllamaModel",)
    DEFAULT_PORT = 11434
    model: OllamaModel  # SUPPORTED_MODELS: the base class refuses any other spec

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 11434, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", *, pull_if_missing: bool = True,
                 **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        self.pull_if_missing = bool(pull_if_missing)
        self._http = HTTPTransport(self.url, timeout=self.inference_timeout, connect_timeout=self.connect_timeout,
                                   context=self._error_context())

    def _extra_serialized(self) -> dict[str, Any]:
        return {"pull_if_missing": self.pull_if_missing}

    @property
    def checkpoint(self) -> str:
        return self.model.checkpoint

    def close(self) -> None:
        self._http.close()

    # ------------------------------------------------------------------ model management
    def _check_connection(self) -> None:
        body = self._http.request_json("GET", "/api/tags")
        if not isinstance(body, dict) or not isinstance(body.get("models"), list):
            raise MalformedResponseError("an /api/tags object with 'models'", body, **self._http.context_for("/api/tags"))

    def list_models(self) -> list[str]:
        body = self._http.request_json("GET", "/api/tags")
        return [m.get("name", "") for m in body.get("models", [])]

    def show(self) -> dict[str, Any]:
        """Model details (``/api/show``); raises ModelNotFoundError if the tag is unknown."""
        try:
            body = self._http.request_json("POST", "/api/show", json={"model": self.checkpoint})
        except ModelServerError as exc:
            if exc.status == 404:
                raise ModelNotFoundError(f"Ollama does not have {self.checkpoint!r}", **self._http.context_for("/api/show")) from None
            raise
        if not isinstance(body, dict):
            raise MalformedResponseError("an /api/show object", body, **self._http.context_for("/api/show"))
        return body

    def pull(self) -> None:
        """Download the tag on the server (``/api/pull``); slow, so it uses ``init_timeout``."""
        path = "/api/pull"
        body = self._http.request_json("POST", path, json={"model": self.checkpoint, "stream": False},
                                       timeout=self.init_timeout or max(self.inference_timeout, 600.0))
        if not isinstance(body, dict) or body.get("status") != "success":
            raise ModelNotFoundError(f"pull of {self.checkpoint!r} failed: {body!r}", **self._http.context_for(path))

    def preload(self) -> None:
        """Load the model into memory now and keep it for ``model.keep_alive``."""
        self._http.request_json("POST", "/api/generate", json={"model": self.checkpoint, "keep_alive": self.model.keep_alive},
                                timeout=self.init_timeout or max(self.inference_timeout, 120.0))

    def unload(self) -> None:
        """Ask Ollama to free the model's memory (``keep_alive: 0``)."""
        self._http.request_json("POST", "/api/generate", json={"model": self.checkpoint, "keep_alive": 0})

    def _initialize(self) -> None:
        try:
            self.show()
        except ModelNotFoundError:
            if not self.pull_if_missing:
                raise
            self.logger.info("pulling %s on the Ollama server", self.checkpoint)
            self.pull()
        self.preload()

    def _deinitialize(self) -> None:
        self.unload()

    # ------------------------------------------------------------------ inference
    def _payload(self, request: ChatRequest) -> dict[str, Any]:
        return ollama_codec.build_chat_payload(request, self.checkpoint, self.model.options, keep_alive=self.model.keep_alive)

    def _chat(self, request: ChatRequest) -> ChatResponse:
        body = self._http.request_json("POST", "/api/chat", json=self._payload(request))
        return ollama_codec.parse_chat_response(body, self._http.context_for("/api/chat"))

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        lines = self._http.stream_lines("POST", "/api/chat", json=self._payload(request))
        ctx = self._http.context_for("/api/chat")
        return ollama_codec.parse_chat_stream(self._http.json_lines(lines, "/api/chat"), ctx)

    def _embed(self, request: EmbeddingRequest) -> EmbeddingResponse:
        path = "/api/embed"
        body = self._http.request_json("POST", path, json={"model": self.checkpoint, "input": request.texts,
                                                             "keep_alive": self.model.keep_alive})
        try:
            response = EmbeddingResponse(embeddings=body["embeddings"], model=body.get("model", ""))
        except (KeyError, TypeError, ValueError):
            raise MalformedResponseError("an /api/embed object with 'embeddings'", body, **self._http.context_for(path)) from None
        if response.embeddings.shape[0] != len(request.texts):
            raise MalformedResponseError(f"{len(request.texts)} embeddings", f"{response.embeddings.shape[0]}", **self._http.context_for(path))
        return response
