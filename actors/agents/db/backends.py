"""Two storage backends with one small interface: the embedded store and the HTTP v2 server.

Both take pre-computed embeddings and return Chroma's raw column-oriented dicts, which
``results.py`` turns into typed records. Keeping the backends this thin means the client logic
(embedding, distance checks, id generation) is shared and tested once.
"""
from __future__ import annotations

import logging
import threading
from typing import Any

import numpy as np

from emos.errors import EmosError

from ..errors import MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError
from .spec import ChromaDB

INCLUDE_QUERY = ["documents", "metadatas", "distances"]
INCLUDE_GET = ["documents", "metadatas"]


class CollectionMissing(EmosError, LookupError):
    pass


#: chromadb keeps one shared system per path and creating it is not thread-safe: components
#: running as threads of one process open their stores under this lock.
_OPEN_LOCK = threading.Lock()


def _forget_failed_store(path: str) -> None:
    """Chroma caches one System per path before starting it: when starting fails (a read-only
    or corrupt directory) the broken System stays cached and every later open of that path gets
    it, failing with unrelated AttributeErrors. Drop it, so a retry fails (or succeeds) afresh."""
    try:
        from chromadb.api.shared_system_client import SharedSystemClient
        from chromadb.config import Settings

        identifier = SharedSystemClient._get_identifier_from_settings(Settings(is_persistent=True, persist_directory=path))
        SharedSystemClient._identifier_to_system.pop(identifier, None)
    except (ImportError, AttributeError, ValueError) as exc:  # another chromadb version: nothing cached the same way
        logging.getLogger("emos.agents.db").debug("cannot clear chromadb's cache for %s: %s", path, exc)


class EmbeddedBackend:
    """``chromadb.PersistentClient`` in this process, persisted under ``db.path``."""

    def __init__(self, db: ChromaDB) -> None:
        try:
            import chromadb
            from chromadb.config import Settings
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("the embedded vector store needs chromadb: pip install 'emos[agents]'") from exc
        from chromadb import errors

        self._errors = errors
        # anonymized_telemetry off: a robot must not try to phone home.
        with _OPEN_LOCK:
            try:
                self._client = chromadb.PersistentClient(
                    path=db.path, settings=Settings(anonymized_telemetry=False, allow_reset=True),
                    tenant=db.tenant, database=db.database)
            except Exception:
                _forget_failed_store(db.path)
                raise
        self._collections: dict[str, Any] = {}

    def heartbeat(self) -> None:
        self._client.heartbeat()

    def open(self, name: str, space: str, create: bool) -> tuple[Any, str]:
        """Return (handle, actual space) of a collection, creating it with ``space`` if asked."""
        col = self._collections.get(name)
        if col is None:
            if create:
                # embedding_function=None: we embed ourselves; Chroma's default would download a model.
                col = self._client.get_or_create_collection(
                    name, embedding_function=None,
                    configuration={"hnsw": {"space": space}})  # type: ignore[arg-type]  # TypedDict
            else:
                try:
                    col = self._client.get_collection(name, embedding_function=None)
                except self._errors.NotFoundError as exc:
                    raise CollectionMissing(name) from exc
            self._collections[name] = col
        config = col.configuration or {}
        actual = ((config.get("hnsw") or {}).get("space")) or space
        return col, actual

    def _rejected(self, what: str, call):
        """Run ``call``; Chroma's invalid-argument errors become ValueError naming the operation
        (the same error the HTTP backend raises for a 4xx InvalidArgumentError)."""
        try:
            return call()
        except (self._errors.InvalidArgumentError, ValueError) as exc:
            raise ValueError(f"Chroma rejected the {what}: {exc}") from None

    def add(self, col: Any, ids, embeddings, documents, metadatas, upsert: bool) -> None:
        fn = col.upsert if upsert else col.add
        self._rejected("upsert" if upsert else "add", lambda: fn(
            ids=ids, embeddings=embeddings, documents=documents, metadatas=metadatas))

    def query(self, col: Any, embeddings: np.ndarray, n_results: int, where: dict | None) -> dict:
        return dict(self._rejected("query", lambda: col.query(
            query_embeddings=embeddings, n_results=n_results, where=where, include=INCLUDE_QUERY)))

    def get(self, col: Any, ids: list[str] | None, where: dict | None, limit: int | None) -> dict:
        return dict(self._rejected("metadata query", lambda: col.get(
            ids=ids, where=where, limit=limit, include=INCLUDE_GET)))

    def delete(self, col: Any, ids: list[str] | None, where: dict | None) -> None:
        self._rejected("delete", lambda: col.delete(ids=ids, where=where))

    def count(self, col: Any) -> int:
        return int(col.count())

    def drop(self, name: str) -> None:
        self._collections.pop(name, None)
        try:
            self._client.delete_collection(name)
        except self._errors.NotFoundError:  # already absent: dropping is idempotent
            pass

    def close(self) -> None:
        self._collections.clear()


class HTTPBackend:
    """A ``chroma run`` server through its HTTP v2 API, over httpx."""

    def __init__(self, db: ChromaDB) -> None:
        import httpx

        self._httpx = httpx
        self._base = f"/tenants/{db.tenant}/databases/{db.database}"
        self.url = db.server_url
        self._http = httpx.Client(base_url=db.server_url, timeout=db.request_timeout)
        self._ids: dict[str, tuple[str, str]] = {}

    def _call(self, method: str, path: str, json: Any = None, missing_ok: bool = False) -> Any:
        httpx = self._httpx
        where = {"client": "ChromaClient", "url": self.url + path}
        try:
            response = self._http.request(method, path, json=json)
        except httpx.TimeoutException as exc:
            raise ModelTimeoutError(f"Chroma server did not answer in time ({exc})", **where) from None
        except httpx.TransportError as exc:
            raise ModelConnectionError(f"cannot reach the Chroma server ({exc})", **where) from None
        if response.status_code == 404 and missing_ok:
            raise CollectionMissing(path)
        if response.status_code >= 400:
            body = response.text
            if response.status_code < 500 and _error_kind(response) == "InvalidArgumentError":
                raise ValueError(f"Chroma rejected the request to {path}: {_error_message(response)}")
            raise ModelServerError("Chroma request failed", status=response.status_code, body=body, **where)
        try:
            return response.json()
        except ValueError:
            raise MalformedResponseError("a JSON body", response.text, **where) from None

    def heartbeat(self) -> None:
        body = self._call("GET", "/heartbeat")
        if not isinstance(body, dict) or "nanosecond heartbeat" not in body:
            raise MalformedResponseError("a Chroma heartbeat", body, client="ChromaClient", url=self.url)

    def open(self, name: str, space: str, create: bool) -> tuple[str, str]:
        cached = self._ids.get(name)
        if cached is None:
            if create:
                body = self._call("POST", f"{self._base}/collections", json={
                    "name": name, "metadata": None, "get_or_create": True,
                    "configuration": {"hnsw": {"space": space}}})
            else:
                body = self._call("GET", f"{self._base}/collections/{name}", missing_ok=True)
            try:
                config = body.get("configuration_json") or {}
                cached = (str(body["id"]), ((config.get("hnsw") or {}).get("space")) or space)
            except (AttributeError, KeyError, TypeError):
                raise MalformedResponseError("a collection object with an id", body,
                                             client="ChromaClient", url=self.url) from None
            self._ids[name] = cached
        return cached

    def _path(self, col: str, verb: str) -> str:
        return f"{self._base}/collections/{col}/{verb}"

    def add(self, col: str, ids, embeddings, documents, metadatas, upsert: bool) -> None:
        self._call("POST", self._path(col, "upsert" if upsert else "add"), json={
            "ids": ids, "embeddings": np.asarray(embeddings, dtype=np.float32).tolist(),
            "documents": documents, "metadatas": metadatas})

    def query(self, col: str, embeddings: np.ndarray, n_results: int, where: dict | None) -> dict:
        return self._checked(self._call("POST", self._path(col, "query"), json={
            "query_embeddings": np.asarray(embeddings, dtype=np.float32).tolist(),
            "n_results": n_results, "where": where, "include": INCLUDE_QUERY}))

    def get(self, col: str, ids: list[str] | None, where: dict | None, limit: int | None) -> dict:
        return self._checked(self._call("POST", self._path(col, "get"), json={
            "ids": ids, "where": where, "limit": limit, "include": INCLUDE_GET}))

    def delete(self, col: str, ids: list[str] | None, where: dict | None) -> None:
        self._call("POST", self._path(col, "delete"), json={"ids": ids, "where": where})

    def count(self, col: str) -> int:
        body = self._call("GET", self._path(col, "count"))
        if isinstance(body, bool) or not isinstance(body, int):
            raise MalformedResponseError("an integer count", body, client="ChromaClient", url=self.url)
        return body

    def drop(self, name: str) -> None:
        self._ids.pop(name, None)
        try:
            self._call("DELETE", f"{self._base}/collections/{name}", missing_ok=True)
        except CollectionMissing:
            pass

    def close(self) -> None:
        self._http.close()

    def _checked(self, body: Any) -> dict:
        if not isinstance(body, dict) or not isinstance(body.get("ids"), list):
            raise MalformedResponseError('a result object with an "ids" list', body,
                                         client="ChromaClient", url=self.url)
        return body


def _error_kind(response) -> str:
    try:
        return str(response.json().get("error", ""))
    except (ValueError, AttributeError):
        return ""


def _error_message(response) -> str:
    try:
        return str(response.json().get("message", response.text))
    except (ValueError, AttributeError):
        return response.text
