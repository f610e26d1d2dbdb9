"""A local model standing by for a failover: loaded and warmed ahead of time, off every loop.

What makes ``fallback_to_local()`` fast: the swap from a dead model server to the local model
is only as fast as the local model's first answer. Loading the GGUF when the server has died
costs seconds (measured 12.9 s on a busy 2-core machine), and so does the first answer of a
freshly loaded model (llama.cpp allocates its compute graph and the kernel pages the
memory-mapped weights in on first use). So an LLM whose ladder holds ``fallback_to_local`` (or
that keeps ``enable_local_model`` beside a server) loads the model at activation in a thread of
its own, then runs one throw-away generation over the component's system prompt: the weights
are paged in, the graph is built, and llama.cpp's prefix cache already holds the system prompt,
so the first real question only evaluates its own tokens.

Activation is not delayed and the primary model keeps answering meanwhile. A load that fails
is reported (an error log naming the component and the file, kept in :attr:`error`), never
swallowed; ``fallback_to_local()`` then tries to load again in the component's worker.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any

from ..errors import ModelClientError
from ..types import ChatMessage, ChatRequest
from .local_client import LocalLLMClient

__all__ = ["LocalStandby"]


class LocalStandby:
    """Loads and warms one :class:`LocalLLMClient` in a daemon thread."""

    def __init__(self, client: LocalLLMClient, component: str, logger: logging.Logger | Any,
                 system_prompt: str | None = None) -> None:
        self.client = client
        self.component = component
        self.logger = logger
        self.system_prompt = system_prompt
        #: why the last load failed (None: loaded, or still loading)
        self.error: str | None = None
        #: seconds the load and the warm-up took (None until done)
        self.load_s: float | None = None
        self.warm_s: float | None = None
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name=f"{self.component}-local-model", daemon=True)
        self._thread.start()

    def wait(self, timeout: float | None = None) -> bool:
        """True once the load (and warm-up) has ended, successfully or not."""
        return self._done.wait(timeout)

    @property
    def ready(self) -> bool:
        return self._done.is_set() and self.error is None and self.client.loaded

    def stop(self, timeout: float = 60.0) -> None:
        """Wait for a load in progress to end (the caller frees the model afterwards)."""
        thread = self._thread
        if thread is not None and thread.is_alive():
            thread.join(timeout)
            if thread.is_alive():
                self.logger.warning("[%s] the local model %s was still loading %.0f s after deactivation",
                                    self.component, self.client.path, timeout)

    def _run(self) -> None:
        try:
            start = time.perf_counter()
            try:
                self.client.initialize()
            except Exception as exc:  # any cause: kept and logged, never lost in a thread
                self.error = f"{type(exc).__name__}: {exc}"
                self.logger.error("[%s] the local model standing by for fallback_to_local() could not be loaded "
                                  "from %s: %s", self.component, self.client.path, self.error)
                return
            self.load_s = time.perf_counter() - start
            start = time.perf_counter()
            try:
                self._warm()
            except (ModelClientError, ValueError, RuntimeError) as exc:  # loaded, but the first answer will be slower
                self.logger.warning("[%s] warming the local model %s failed: %s", self.component, self.client.path, exc)
            else:
                self.warm_s = time.perf_counter() - start
            self.logger.info("[%s] local model %s standing by (loaded in %.2f s, warmed in %.2f s)", self.component,
                             self.client.path.name, self.load_s, self.warm_s or float("nan"))
        finally:
            self._done.set()

    def _warm(self) -> None:
        messages = [ChatMessage(role="system", content=self.system_prompt)] if self.system_prompt else []
        messages.append(ChatMessage(role="user", content="Hello."))
        self.client.chat(ChatRequest(messages=messages, temperature=0.0, max_tokens=1))

    def __deepcopy__(self, memo: dict) -> None:
        # A threaded restart copies its component: the copy starts its own standby at its
        # activation (a running thread and a loaded model are not copied).
        return None
