"""Embedding backends for the vector store: the local sentence-transformers model or Ollama."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import httpx
import numpy as np

from ..errors import MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError
from .spec import ChromaDB


class Embedder(Protocol):
    def embed(self, texts: Sequence[str]) -> np.ndarray: ...


class OllamaEmbedder:
    """Embeds through an Ollama server's ``POST /api/embed`` (batched ``input`` list)."""

    def __init__(self, model: str, host: str = "127.0.0.1", port: int = 11434, timeout: float = 30.0) -> None:
        self.model = model
        self.url = f"http://{host}:{port}/api/embed"
        self._http = httpx.Client(timeout=timeout)

    def embed(self, texts: Sequence[str]) -> np.ndarray:
        texts = list(texts)
        if not texts:
            return np.zeros((0, 0), dtype=np.float32)
        where = {"client": "OllamaEmbedder", "model": self.model, "url": self.url}
        try:
            response = self._http.post(self.url, json={"model": self.model, "input": texts})
        except httpx.TimeoutException as exc:
            raise ModelTimeoutError(f"embedding request timed out ({exc})", **where) from None
        except httpx.TransportError as exc:
            raise ModelConnectionError(f"cannot reach the Ollama server ({exc})", **where) from None
        if response.status_code >= 400:
            raise ModelServerError("embedding request failed", status=response.status_code,
                                   body=response.text, **where)
        try:
            vectors = np.asarray(response.json()["embeddings"], dtype=np.float32)
        except (ValueError, KeyError, TypeError):
            raise MalformedResponseError('a JSON object with "embeddings"', response.text, **where) from None
        if vectors.ndim != 2 or vectors.shape[0] != len(texts):
            raise MalformedResponseError(f"{len(texts)} embedding rows", f"shape {vectors.shape}", **where)
        return vectors

    def close(self) -> None:
        self._http.close()


def make_embedder(db: ChromaDB) -> Embedder:
    """The embedding backend the spec names (loads the local model on first use)."""
    if db.embeddings == "ollama":
        return OllamaEmbedder(db.embedding_checkpoint or "nomic-embed-text", db.ollama_host,
                              db.ollama_port, db.request_timeout)
    from ..local.embeddings import SentenceEmbedder

    return SentenceEmbedder(db.checkpoint)
