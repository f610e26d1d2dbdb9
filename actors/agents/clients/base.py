"""The one interface every model client implements, plus retries and cross-process rebuild.

Lifecycle, as components drive it: ``check_connection()`` at configure, ``initialize()`` at
activation when ``init_on_activation`` is set, ``inference(request)`` per step,
``deinitialize()`` at deactivation. Nothing touches the network in ``__init__``: a client is
cheap to build in a recipe, then :meth:`serialize` turns it into a plain dict that
:func:`client_from_serialized` rebuilds inside the component's own process.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any, ClassVar, TypeVar

from emos.core.retry import Backoff, retry

from ..errors import ErrorContext, ModelClientError, ModelConnectionError, ModelServerError, ModelTimeoutError
from ..models import Model, model_from_dict
from ..types import (
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

__all__ = ["ModelClient", "client_from_serialized", "CLIENT_TYPES"]

T = TypeVar("T")

#: class name -> client class; filled by subclasses, used by client_from_serialized.
CLIENT_TYPES: dict[str, type[ModelClient]] = {}

LOG_LEVELS = ("debug", "info", "warn", "warning", "error", "fatal")

# Statuses worth retrying: the server (or a proxy in front of it) is momentarily unable.
RETRYABLE_STATUS = frozenset({408, 429, 502, 503, 504})


def _positive(name: str, value: Any, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0:
        raise ValueError(f"{name}: expected a positive number of seconds, got {value!r}")


class ModelClient:
    """Base class. Subclasses set ``SUPPORTED_MODELS`` and implement the ``_`` hooks."""

    #: model spec class names this client can serve; empty means any.
    SUPPORTED_MODELS: ClassVar[tuple[str, ...]] = ()
    DEFAULT_PORT: ClassVar[int | None] = 8000

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        CLIENT_TYPES[cls.__name__] = cls

    def __init__(
        self,
        model: Model | dict,
        host: str = "127.0.0.1",
        port: int | None = None,
        inference_timeout: float = 30,
        init_on_activation: bool = True,
        logging_level: str = "info",
        *,
        connect_timeout: float = 5.0,
        max_retries: int = 0,
        retry_backoff: float = 0.5,
    ) -> None:
        if isinstance(model, dict):
            model = model_from_dict(model)
        if not isinstance(model, Model):
            raise TypeError(f"{type(self).__name__}.model: expected a model spec (e.g. OllamaModel), got {type(model).__name__}")
        if self.SUPPORTED_MODELS and model.model_type not in self.SUPPORTED_MODELS:
            raise TypeError(
                f"{type(self).__name__} cannot serve a {model.model_type}; expected one of {self.SUPPORTED_MODELS}"
            )
        if not isinstance(host, str) or not host:
            raise ValueError(f"{type(self).__name__}.host: expected a host name or URL, got {host!r}")
        has_scheme = host.startswith(("http://", "https://", "ws://", "wss://"))
        # A full URL (https://api.openai.com) may omit the port; a bare host gets the default.
        port = self.DEFAULT_PORT if port is None and not has_scheme else port
        if port is not None and (isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536):
            raise ValueError(f"{type(self).__name__}.port: expected an integer in 1..65535, got {port!r}")
        _positive(f"{type(self).__name__}.inference_timeout", inference_timeout)
        _positive(f"{type(self).__name__}.connect_timeout", connect_timeout)
        if isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 0:
            raise ValueError(f"{type(self).__name__}.max_retries: expected an integer >= 0, got {max_retries!r}")
        if isinstance(retry_backoff, bool) or not isinstance(retry_backoff, (int, float)) or not retry_backoff >= 0:
            raise ValueError(f"{type(self).__name__}.retry_backoff: expected a number of seconds >= 0, got {retry_backoff!r}")
        if logging_level.lower() not in LOG_LEVELS:
            raise ValueError(f"{type(self).__name__}.logging_level: expected one of {LOG_LEVELS}, got {logging_level!r}")
        self.model = model
        self.model_name = model.name
        self.model_type = model.model_type
        self.host = host
        self.port = port
        self.inference_timeout = float(inference_timeout)
        self.init_on_activation = bool(init_on_activation)
        self.logging_level = logging_level
        self.connect_timeout = float(connect_timeout)
        self.max_retries = max_retries
        self.retry_backoff = float(retry_backoff)
        self.initialized = False
        self.logger = logging.getLogger(f"emos.agents.{type(self).__name__}.{self.model_name}")
        self.logger.setLevel({"warn": "WARNING", "fatal": "CRITICAL"}.get(logging_level.lower(), logging_level.upper()))

    # ------------------------------------------------------------------ identity
    @property
    def init_timeout(self) -> float | None:
        return self.model.init_timeout

    @property
    def url(self) -> str:
        """Base URL of the server (scheme://host:port)."""
        if self.host.startswith(("http://", "https://", "ws://", "wss://")):
            base = self.host.rstrip("/")
            if self.port is None:
                return base
            scheme, _, rest = base.partition("://")
            authority, slash, path = rest.partition("/")
            if ":" not in authority:  # add the port unless the URL already names one
                authority = f"{authority}:{self.port}"
            return f"{scheme}://{authority}{slash}{path}"
        return f"http://{self.host}:{self.port}" if self.port else f"http://{self.host}"

    def _error_context(self, url: str | None = None) -> ErrorContext:
        return {"client": type(self).__name__, "model": self.model_name, "url": url or self.url}

    # ------------------------------------------------------------------ public API
    def check_connection(self) -> None:
        """Raise a typed error unless the server answers."""
        self._retrying(self._check_connection)

    def initialize(self) -> None:
        """Load / prepare the model on the server."""
        self._retrying(self._initialize)
        self.initialized = True

    def inference(self, request: Any) -> Any:
        """Run one request. Chat with ``stream=True`` returns an iterator of :class:`ChatChunk`."""
        if isinstance(request, ChatRequest):
            if request.stream:
                # Streams are not retried: a retry after partial output would repeat text the
                # component has already published.
                return self._chat_stream(request)
            return self._retrying(lambda: self._chat(request))
        if isinstance(request, EmbeddingRequest):
            return self._retrying(lambda: self._embed(request))
        if isinstance(request, SpeechRequest):
            return self._retrying(lambda: self._speech(request))
        if isinstance(request, TranscriptionRequest):
            return self._retrying(lambda: self._transcribe(request))
        return self._retrying(lambda: self._other_inference(request))

    def deinitialize(self) -> None:
        """Unload the model (best effort on the server) and release local resources."""
        try:
            self._deinitialize()
        finally:
            self.initialized = False
            self.close()

    def close(self) -> None:
        """Release sockets; the client can still be used afterwards (it reconnects)."""

    # convenience wrappers with precise return types
    def chat(self, request: ChatRequest) -> ChatResponse:
        if request.stream:
            raise ValueError("chat(): request.stream is True; use chat_stream()")
        return self.inference(request)

    def chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        if not request.stream:
            request = ChatRequest(
                messages=request.messages, tools=request.tools, stream=True, temperature=request.temperature,
                max_tokens=request.max_tokens, options=request.options, task=request.task,
            )
        return self.inference(request)

    def embed(self, texts: list[str] | str) -> EmbeddingResponse:
        return self.inference(EmbeddingRequest(texts))

    # ------------------------------------------------------------------ serialization
    def serialize(self) -> dict[str, Any]:
        """A msgpack/JSON-able dict; :func:`client_from_serialized` rebuilds the client."""
        return {
            "client_type": type(self).__name__,
            "model": self.model.to_dict(),
            "host": self.host,
            "port": self.port,
            "inference_timeout": self.inference_timeout,
            "init_on_activation": self.init_on_activation,
            "logging_level": self.logging_level,
            "connect_timeout": self.connect_timeout,
            "max_retries": self.max_retries,
            "retry_backoff": self.retry_backoff,
            **self._extra_serialized(),
        }

    def _extra_serialized(self) -> dict[str, Any]:
        return {}

    @classmethod
    def from_serialized(cls, data: dict[str, Any]) -> ModelClient:
        return client_from_serialized(data)

    # ------------------------------------------------------------------ retries
    def _retrying(self, call: Callable[[], T]) -> T:
        """Run ``call``, retrying connection failures, timeouts and transient statuses."""
        return retry(
            call, Backoff(attempts=self.max_retries + 1, base=self.retry_backoff, factor=2.0),
            retry_on=(ModelConnectionError, ModelTimeoutError, ModelServerError),
            retry_if=lambda exc: not isinstance(exc, ModelServerError) or exc.status in RETRYABLE_STATUS,
            on_retry=lambda exc, attempt, delay: self.logger.warning("attempt %d failed (%s); retrying in %.2fs", attempt, exc, delay),
        )

    # ------------------------------------------------------------------ hooks
    def _check_connection(self) -> None:
        raise NotImplementedError

    def _initialize(self) -> None:
        """Default: nothing to load."""

    def _deinitialize(self) -> None:
        """Default: nothing to unload."""

    def _unsupported(self, what: str) -> ModelClientError:
        return ModelClientError(f"{what} is not supported by {type(self).__name__}", **self._error_context())

    def _chat(self, request: ChatRequest) -> ChatResponse:
        raise self._unsupported("chat")

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        raise self._unsupported("streamed chat")

    def _embed(self, request: EmbeddingRequest) -> EmbeddingResponse:
        raise self._unsupported("embeddings")

    def _speech(self, request: SpeechRequest) -> SpeechResponse:
        raise self._unsupported("speech synthesis")

    def _transcribe(self, request: TranscriptionRequest) -> TranscriptionResponse:
        raise self._unsupported("transcription")

    def _other_inference(self, request: Any) -> Any:
        raise TypeError(f"{type(self).__name__}.inference: unsupported request type {type(request).__name__}")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(model={self.model_name!r}, url={self.url!r})"


def client_from_serialized(data: dict[str, Any]) -> ModelClient:
    """Rebuild a client from :meth:`ModelClient.serialize` output (e.g. in a child process)."""
    if not isinstance(data, dict) or "client_type" not in data:
        raise ValueError(f"serialized client: expected a dict with 'client_type', got {data!r}")
    fields = dict(data)
    kind = fields.pop("client_type")
    # Importing the package registers every client class.
    from . import _register_all

    _register_all()
    cls = CLIENT_TYPES.get(kind)
    if cls is None:
        raise ValueError(f"serialized client: unknown client_type {kind!r}; expected one of {sorted(CLIENT_TYPES)}")
    return cls(**fields)
