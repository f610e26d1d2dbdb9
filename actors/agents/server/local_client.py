"""A model client that runs a GGUF language model inside the calling process (llama.cpp).

What ``LLM(..., enable_local_model=True)`` and ``fallback_to_local()`` use: the same client
interface as the HTTP clients (``check_connection``, ``initialize``, ``inference``), so the
component's retries, failover and ladders treat it as any other client, but no server is
involved and nothing leaves the process. The file is checked when the client is built (a
recipe line with a missing or corrupt GGUF fails there, naming the file); the model is loaded
by ``initialize()``, which components call in their worker thread, never on the event loop.
"""
from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any, ClassVar

import attrs

from ..clients.base import ModelClient
from ..errors import ModelClientError, ModelConnectionError
from ..models.base import Model
from ..types import ChatChunk, ChatRequest, ChatResponse
from .gguf import SMOLLM2_NAMES, LocalModelError, LocalModelUnavailable, check_gguf, packaged_smollm2, require_llama_cpp

__all__ = ["LocalLLM", "LocalLLMClient", "LOCAL_CLIENT", "local_client_for"]

#: the name the local client has among a component's model clients
LOCAL_CLIENT = "local"


def _threads(instance: Any, attribute: Any, value: Any) -> None:
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 256):
        raise ValueError(f"LocalLLM.{attribute.name}: expected None (automatic) or 1..256 threads, got {value!r}")


def _context(instance: Any, attribute: Any, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 256 <= value <= 131072:
        raise ValueError(f"LocalLLM.{attribute.name}: expected a context size of 256..131072 tokens, got {value!r}")


@attrs.define(kw_only=True)
class LocalLLM(Model):
    """A GGUF chat model run in-process. ``checkpoint`` is the file ("" = the packaged SmolLM2)."""

    name: str = attrs.field(default=SMOLLM2_NAMES[2])
    checkpoint: str = attrs.field(default="", validator=attrs.validators.instance_of(str))
    n_threads: int | None = attrs.field(default=None, validator=_threads)
    n_ctx: int = attrs.field(default=2048, validator=_context)

    INIT_FIELDS = ("checkpoint", "n_threads", "n_ctx")


class LocalLLMClient(ModelClient):
    """Chat (plain and streamed) with a local GGUF model; one request at a time."""

    SUPPORTED_MODELS: ClassVar[tuple[str, ...]] = ("LocalLLM",)
    DEFAULT_PORT: ClassVar[int | None] = None

    def __init__(self, model: LocalLLM | dict | None = None, host: str = "in-process", port: int | None = None,
                 **kwargs: Any) -> None:
        super().__init__(model if model is not None else LocalLLM(), host=host, port=port, **kwargs)
        self.model: LocalLLM
        # Checked here, at definition: the recipe line names the missing or corrupt file.
        self.path = check_gguf(self.model.checkpoint) if self.model.checkpoint else packaged_smollm2()
        check_gguf(self.path)
        require_llama_cpp()
        self._responder: Any = None
        self._load_lock = threading.Lock()

    @property
    def url(self) -> str:
        return f"local://{self.path}"

    @property
    def loaded(self) -> bool:
        return self._responder is not None

    # ------------------------------------------------------------------ hooks
    def _check_connection(self) -> None:
        # "Reachable" = the file is still there and still a GGUF model (it may have been
        # replaced since the recipe was written); loading it is initialize()'s job.
        try:
            check_gguf(self.path)
        except LocalModelError as exc:
            raise ModelConnectionError(str(exc), **self._error_context()) from None

    def _initialize(self) -> None:
        with self._load_lock:
            if self._responder is not None:
                return
            from .llama_backend import LlamaCppResponder

            try:
                self._responder = LlamaCppResponder(self.path, n_ctx=self.model.n_ctx, n_threads=self.model.n_threads)
            except (LocalModelError, LocalModelUnavailable) as exc:
                raise ModelConnectionError(str(exc), **self._error_context()) from None

    def _responder_or_load(self) -> Any:
        if self._responder is None:
            self._initialize()
        return self._responder

    def _chat(self, request: ChatRequest) -> ChatResponse:
        responder = self._responder_or_load()
        try:
            return responder.respond(request, self.model_name)
        except ValueError as exc:  # e.g. the prompt does not fit the context window
            raise ModelClientError(f"the local model refused the request: {exc}", **self._error_context()) from None

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        responder = self._responder_or_load()
        try:
            yield from responder.stream(request, self.model_name)
        except ValueError as exc:
            raise ModelClientError(f"the local model refused the request: {exc}", **self._error_context()) from None

    def cancel_generation(self) -> bool:
        """Abandon the answer in progress (if any) without waiting: it stops at its next token and
        raises :class:`~emos.actors.agents.errors.GenerationAbandoned` in the thread that asked.
        ``change_model_client`` calls it when the component switches away from this client."""
        responder = self._responder
        return bool(responder is not None and responder.cancel())

    def _deinitialize(self) -> None:
        with self._load_lock:
            responder, self._responder = self._responder, None
        if responder is not None:
            responder.close()

    def close(self) -> None:
        """Nothing to close between requests: the model stays loaded until deinitialize()."""

    def __deepcopy__(self, memo: dict) -> LocalLLMClient:
        # A threaded restart copies components; the copy loads its own model when used.
        return LocalLLMClient(self.model.to_dict(), **{k: v for k, v in self.serialize().items()
                                                       if k not in ("client_type", "model")})


def local_client_for(path: str | None, n_threads: int | None, n_ctx: int) -> LocalLLMClient:
    """The local client a component config asks for (checked now: errors name the file)."""
    return LocalLLMClient(LocalLLM(checkpoint=path or "", n_threads=n_threads, n_ctx=n_ctx))
