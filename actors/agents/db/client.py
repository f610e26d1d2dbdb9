"""ChromaClient: one API over the embedded store and a ``chroma run`` server."""
from __future__ import annotations

import re
import threading
import uuid
from collections.abc import Sequence
from typing import Any

import attrs
import numpy as np

from ..errors import MalformedResponseError, ModelConnectionError
from .backends import CollectionMissing, EmbeddedBackend, HTTPBackend
from .embedding import Embedder, make_embedder
from .results import Hit, Record, hits_from_query, records_from_get
from .spec import DISTANCES, ChromaDB

# Chroma's own rule for collection names, checked here to fail before any I/O.
_BATCH = 1000
_NAME = re.compile(r"^[a-zA-Z0-9][a-zA-Z0-9._-]{1,510}[a-zA-Z0-9]$")


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"collection name {name!r}: expected 3-512 characters of [a-zA-Z0-9._-], "
                         "starting and ending with a letter or digit")
    return name


def _check_distance(distance: str) -> str:
    if distance not in DISTANCES:
        raise ValueError(f"distance {distance!r}: expected one of {DISTANCES}")
    return distance


class ChromaClient:
    """Vector-store client: add, upsert, query, metadata query, delete, reset.

    Collections are created on first write with the requested distance (Chroma fixes a
    collection's space at creation); asking for another distance later is an error rather than
    silently returning distances in the wrong space.
    """

    def __init__(self, db: ChromaDB, embedder: Embedder | None = None) -> None:
        if not isinstance(db, ChromaDB):
            raise TypeError(f"ChromaClient.db: expected a ChromaDB spec, got {type(db).__name__}")
        self.db = db
        self._embedder = embedder
        self._backend: EmbeddedBackend | HTTPBackend | None = None
        self._lock = threading.RLock()
        self._users = 0
        self._warm = False  # the embedder has embedded once (see load_embedder)

    # ------------------------------------------------------------------ lifecycle
    def initialize(self) -> None:
        """Make the client ready to serve: open the store (and check a server answers), then
        load the embedding model (see :meth:`load_embedder`). Each successful call is balanced
        by one :meth:`deinitialize`: components sharing one client (threads of one process)
        keep it open until the last of them lets go."""
        with self._lock:
            self._open_store()
            self.load_embedder()
            self._users += 1

    def _open_store(self) -> None:
        with self._lock:
            try:
                self._open_backend().heartbeat()
            except (ModelConnectionError, ImportError):
                raise
            except Exception as exc:
                if self.db.is_server:
                    raise
                # Name the store: Chroma's own message ("attempt to write a readonly database")
                # does not say which of a robot's directories it means.
                self._backend = None
                raise ModelConnectionError(f"cannot open the embedded store at {self.db.path!r} ({exc})",
                                           client="ChromaClient") from exc

    def load_embedder(self) -> None:
        """Load the embedding model now and embed one short text, so that the first real write
        or query does not pay for it: loading all-MiniLM-L6-v2 (torch and its weights) took
        17-85 s on a loaded 2-core machine, and a first map write that paid for it blocked for
        85 s. With Ollama embeddings the one request makes the server load its model (and
        fails here, typed, if the server cannot be reached). Idempotent and cheap once loaded."""
        with self._lock:
            if self._warm:
                return
            vectors = np.asarray(self.embedder.embed(["ready"]))
            if vectors.ndim != 2 or vectors.shape[0] != 1:
                raise MalformedResponseError("one embedding row for one text", f"shape {vectors.shape}",
                                             client="ChromaClient")
            self._warm = True

    def _open_backend(self) -> EmbeddedBackend | HTTPBackend:
        with self._lock:
            if self._backend is None:
                self._backend = HTTPBackend(self.db) if self.db.is_server else EmbeddedBackend(self.db)
            return self._backend

    def check_connection(self) -> None:
        """Raise ModelConnectionError (or ModelTimeoutError) if the store cannot be reached."""
        self.initialize()

    def deinitialize(self) -> None:
        with self._lock:
            self._users = max(0, self._users - 1)
            if self._backend is not None and self._users == 0:
                self._backend.close()
                self._backend = None

    @property
    def embedder(self) -> Embedder:
        if self._embedder is None:
            self._embedder = make_embedder(self.db)
        return self._embedder

    def embed(self, texts: Sequence[str]) -> np.ndarray:
        return self.embedder.embed(list(texts))

    # ------------------------------------------------------------------ writes
    def add(self, collection_name: str, documents: Sequence[str], metadatas: Sequence[dict] | None = None,
            ids: Sequence[str] | None = None, distance_func: str = "l2",
            embeddings: np.ndarray | None = None) -> list[str]:
        """Store documents (embedded here unless ``embeddings`` are given); returns their ids.

        Chroma ignores an ``add`` whose id exists; use :meth:`upsert` to overwrite.
        """
        return self._write(collection_name, documents, metadatas, ids, distance_func, embeddings, upsert=False)

    def upsert(self, collection_name: str, documents: Sequence[str], metadatas: Sequence[dict] | None = None,
               ids: Sequence[str] | None = None, distance_func: str = "l2",
               embeddings: np.ndarray | None = None) -> list[str]:
        """Insert or overwrite documents by id; returns their ids."""
        return self._write(collection_name, documents, metadatas, ids, distance_func, embeddings, upsert=True)

    def _write(self, name, documents, metadatas, ids, distance, embeddings, upsert) -> list[str]:
        documents = _texts("documents", documents)
        n = len(documents)
        ids = [uuid.uuid4().hex for _ in range(n)] if ids is None else [str(i) for i in ids]
        if len(ids) != n or len(set(ids)) != n:
            raise ValueError(f"ids: expected {n} distinct ids (one per document), got {len(ids)} "
                             f"with {len(set(ids))} distinct")
        metas = None
        if metadatas is not None:
            metas = [dict(m) if m else None for m in metadatas]
            if len(metas) != n:
                raise ValueError(f"metadatas: expected {n} entries (one per document), got {len(metas)}")
        vectors = self._vectors(documents, embeddings)
        if n == 0:
            return []
        col = self._open(name, distance, create=True)
        # Chroma caps one request's batch (a few thousand rows): send large writes in slices.
        for start in range(0, n, _BATCH):
            end = start + _BATCH
            self._store().add(col, ids[start:end], vectors[start:end], documents[start:end],
                              None if metas is None else metas[start:end], upsert)
        return ids

    # ------------------------------------------------------------------ reads
    def query(self, collection_name: str, query: str, n_results: int = 1, distance_func: str = "l2",
              where: dict | None = None) -> list[Hit]:
        """The ``n_results`` nearest entries to one query text, closest first."""
        if not isinstance(query, str):
            raise TypeError(f"query: expected one str (use query_many for a list), got {type(query).__name__}")
        return self.query_many(collection_name, [query], n_results, distance_func, where)[0]

    def query_many(self, collection_name: str, queries: Sequence[str], n_results: int = 1,
                   distance_func: str = "l2", where: dict | None = None,
                   embeddings: np.ndarray | None = None) -> list[list[Hit]]:
        """One hit list per query text, in the order given."""
        if isinstance(n_results, bool) or not isinstance(n_results, int) or n_results < 1:
            raise ValueError(f"n_results: expected a positive integer, got {n_results!r}")
        queries = _texts("queries", queries)
        vectors = self._vectors(queries, embeddings)
        try:
            col = self._open(collection_name, distance_func, create=False)
        except CollectionMissing:
            return [[] for _ in queries]
        if not queries:
            return []
        raw = self._store().query(col, vectors, n_results, where)
        return [hits_from_query(raw, i) for i in range(len(queries))]

    def metadata_query(self, collection_name: str, where: dict | None = None, ids: Sequence[str] | None = None,
                       limit: int | None = None) -> list[Record]:
        """Entries whose metadata match a Chroma ``where`` filter (and/or given ids)."""
        if where is not None and not isinstance(where, dict):
            raise TypeError(f"where: expected a Chroma filter dict, got {type(where).__name__}")
        try:
            col = self._open(collection_name, None, create=False)
        except CollectionMissing:
            return []
        raw = self._store().get(col, list(ids) if ids is not None else None, where, limit)
        return records_from_get(raw)

    def count(self, collection_name: str) -> int:
        try:
            return self._backend_count(collection_name)
        except CollectionMissing:
            return 0

    def _backend_count(self, name: str) -> int:
        col = self._open(name, None, create=False)
        return self._store().count(col)

    # ------------------------------------------------------------------ deletes
    def delete(self, collection_name: str, ids: Sequence[str] | None = None, where: dict | None = None) -> None:
        """Delete entries by id and/or metadata filter (one of them is required)."""
        if ids is None and where is None:
            raise ValueError("delete: give ids or a where filter (use reset() to empty a collection)")
        try:
            col = self._open(collection_name, None, create=False)
        except CollectionMissing:
            return
        self._store().delete(col, list(ids) if ids is not None else None, where)

    def reset(self, collection_name: str) -> None:
        """Drop one collection and everything in it (the next write recreates it)."""
        self._store().drop(_check_name(collection_name))

    # ------------------------------------------------------------------ helpers
    def _store(self) -> EmbeddedBackend | HTTPBackend:
        # Used without initialize() (scripts, tests): opened on first use, closed by deinitialize().
        return self._backend if self._backend is not None else self._open_backend()

    def _open(self, name: str, distance: str | None, create: bool) -> Any:
        _check_name(name)
        if distance is not None:
            _check_distance(distance)
        col, actual = self._store().open(name, distance or "l2", create)
        if distance is not None and actual != distance:
            raise ValueError(f"collection {name!r} uses distance {actual!r}, not {distance!r}: "
                             "a collection's distance is fixed when it is created (reset it to change)")
        return col

    def _vectors(self, texts: list[str], embeddings: np.ndarray | None) -> np.ndarray:
        if embeddings is None:
            return self.embed(texts)
        vectors = np.asarray(embeddings, dtype=np.float32)
        if vectors.ndim != 2 or vectors.shape[0] != len(texts):
            raise ValueError(f"embeddings: expected {len(texts)} rows, got shape {vectors.shape}")
        return vectors

    def serialize(self) -> dict[str, Any]:
        """Plain data that rebuilds this client in another process (no live handles)."""
        return {"client_type": type(self).__name__, "db": attrs.asdict(self.db)}

    @classmethod
    def from_serialized(cls, data: dict[str, Any]) -> ChromaClient:
        if not isinstance(data, dict) or data.get("client_type") != cls.__name__ or "db" not in data:
            raise ValueError(f"serialized ChromaClient: expected {{'client_type': 'ChromaClient', 'db': {{...}}}}, "
                             f"got {data!r}")
        return cls(ChromaDB(**data["db"]))

    def __getstate__(self) -> dict:  # pickling keeps the spec only; handles reopen lazily
        return {"db": self.db}

    def __setstate__(self, state: dict) -> None:
        self.db = state["db"]
        self._embedder = None
        self._backend = None
        self._lock = threading.RLock()
        self._users = 0
        self._warm = False


def _texts(what: str, values: Sequence[str]) -> list[str]:
    if isinstance(values, str):
        raise TypeError(f"{what}: expected a list of strings, got one str")
    values = list(values)
    for i, value in enumerate(values):
        if not isinstance(value, str):
            raise TypeError(f"{what}[{i}]: expected str, got {type(value).__name__}")
    return values
