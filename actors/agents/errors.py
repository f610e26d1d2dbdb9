"""Typed errors raised by every model client.

Components map these onto health statuses and fallbacks, so the *kind* of failure matters more
than the text: a refused connection (the server is down, try another model), a timeout (the
server is alive but slow), a server error (it answered with a failing HTTP status) and a
malformed response (it answered, but not in the protocol we speak).

Every error names the client, the model and the URL it talked to, so a log line alone says
which backend failed.
"""
from __future__ import annotations

from typing import TypedDict

from emos.errors import EmosError

__all__ = [
    "ModelClientError",
    "ModelConnectionError",
    "ModelTimeoutError",
    "ModelServerError",
    "MalformedResponseError",
    "ModelNotFoundError",
]


def _where(client: str | None, model: str | None, url: str | None) -> str:
    parts = []
    if client:
        parts.append(f"client {client!r}")
    if model:
        parts.append(f"model {model!r}")
    if url:
        parts.append(f"at {url}")
    return " ".join(parts)


class ErrorContext(TypedDict):
    """The keyword fields every error below takes (clients pass them as ``**context``)."""

    client: str | None
    model: str | None
    url: str | None


class ModelClientError(EmosError):
    """Base class: a model client could not produce a result."""

    def __init__(
        self,
        detail: str,
        *,
        client: str | None = None,
        model: str | None = None,
        url: str | None = None,
    ) -> None:
        self.detail = detail
        self.client = client
        self.model = model
        self.url = url
        where = _where(client, model, url)
        super().__init__(f"{where}: {detail}" if where else detail)

    def __reduce__(self):  # keep the keyword fields when errors cross process boundaries
        return (_rebuild, (type(self), self.detail, self._extra(), self.client, self.model, self.url))

    def _extra(self) -> dict:
        return {}


def _rebuild(cls, detail, extra, client, model, url):
    return cls(detail, client=client, model=model, url=url, **extra)


class ModelConnectionError(ModelClientError):
    """The server could not be reached (refused, DNS failure, reset before any answer)."""


class ModelTimeoutError(ModelClientError):
    """The server accepted the request but did not answer within the configured timeout."""


class ModelServerError(ModelClientError):
    """The server answered with a failing status; carries the status and a body excerpt."""

    #: Longest body excerpt kept in the message; error pages can be megabytes of HTML.
    EXCERPT_CHARS = 300

    def __init__(
        self,
        detail: str,
        *,
        status: int,
        body: str = "",
        client: str | None = None,
        model: str | None = None,
        url: str | None = None,
    ) -> None:
        self.status = int(status)
        self.body = body[: self.EXCERPT_CHARS]
        excerpt = f" body: {self.body!r}" if self.body else ""
        super().__init__(f"{detail} (HTTP {self.status}){excerpt}", client=client, model=model, url=url)
        self.detail = detail

    def _extra(self) -> dict:
        return {"status": self.status, "body": self.body}


class MalformedResponseError(ModelClientError):
    """The server answered, but not with what the protocol promises."""

    def __init__(
        self,
        expected: str,
        got: object,
        *,
        client: str | None = None,
        model: str | None = None,
        url: str | None = None,
    ) -> None:
        self.expected = expected
        self.got = got if isinstance(got, str) else repr(got)
        self.got = self.got[:300]
        super().__init__(f"expected {expected}, got {self.got!r}", client=client, model=model, url=url)

    def __reduce__(self):
        return (_rebuild_malformed, (self.expected, self.got, self.client, self.model, self.url))


def _rebuild_malformed(expected, got, client, model, url):
    return MalformedResponseError(expected, got, client=client, model=model, url=url)


class ModelNotFoundError(ModelClientError):
    """The server is up but does not serve (and could not load) the requested model."""


class GenerationAbandoned(EmosError, RuntimeError):
    """A local model's answer in progress was abandoned: the component switched to another model
    client meanwhile (``change_model_client``, e.g. back from ``fallback_to_local()`` to the
    restarted server). Not a failure of the model: the question goes to the new client."""
