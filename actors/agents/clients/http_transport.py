"""httpx wrapper that turns every transport failure into a typed model-client error.

Clients call :meth:`HTTPTransport.request` / :meth:`HTTPTransport.stream_lines` and never see
an httpx exception: refused connections become :class:`ModelConnectionError`, read timeouts
:class:`ModelTimeoutError`, failing statuses :class:`ModelServerError` (with a body excerpt),
undecodable bodies :class:`MalformedResponseError`.
"""
from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from typing import Any

import httpx

from ..errors import ErrorContext, MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError

__all__ = ["HTTPTransport"]


class HTTPTransport:
    """One lazily-opened ``httpx.Client`` per client object, with typed errors."""

    def __init__(
        self,
        base_url: str,
        *,
        timeout: float,
        connect_timeout: float,
        headers: dict[str, str] | None = None,
        context: ErrorContext,
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self.timeout = timeout
        self.connect_timeout = connect_timeout
        self.headers = headers or {}
        self.context = context
        self._client: httpx.Client | None = None

    @property
    def client(self) -> httpx.Client:
        if self._client is None or self._client.is_closed:
            self._client = httpx.Client(
                base_url=self.base_url,
                headers=self.headers,
                timeout=httpx.Timeout(self.timeout, connect=self.connect_timeout),
            )
        return self._client

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def context_for(self, path: str) -> ErrorContext:
        return {**self.context, "url": f"{self.base_url}{path}"}

    @contextlib.contextmanager
    def _mapped(self, path: str) -> Iterator[None]:
        ctx = self.context_for(path)
        try:
            yield
        except httpx.ConnectTimeout:
            raise ModelConnectionError("timed out while connecting", **ctx) from None
        except httpx.TimeoutException as exc:
            raise ModelTimeoutError(f"no answer within the timeout ({type(exc).__name__})", **ctx) from None
        except httpx.ConnectError as exc:
            raise ModelConnectionError(f"cannot connect ({exc})", **ctx) from None
        except httpx.RemoteProtocolError as exc:
            text = str(exc)
            if "without sending" in text or "disconnected" in text.lower():
                raise ModelConnectionError(f"server closed the connection ({text})", **ctx) from None
            raise MalformedResponseError("a well-formed HTTP response", text, **ctx) from None
        except httpx.TransportError as exc:
            raise ModelConnectionError(f"transport failure ({type(exc).__name__}: {exc})", **ctx) from None

    def _check_status(self, response: httpx.Response, path: str) -> None:
        if response.status_code >= 400:
            try:
                body = response.text
            except (httpx.HTTPError, UnicodeDecodeError):
                body = ""
            raise ModelServerError("server returned an error status", status=response.status_code, body=body, **self.context_for(path))

    def request(self, method: str, path: str, *, timeout: float | None = None, **kwargs: Any) -> httpx.Response:
        """Send a request; returns the response only if its status is < 400."""
        if timeout is not None:
            kwargs["timeout"] = httpx.Timeout(timeout, connect=self.connect_timeout)
        with self._mapped(path):
            response = self.client.request(method, path, **kwargs)
            response.read()
        self._check_status(response, path)
        return response

    def request_json(self, method: str, path: str, **kwargs: Any) -> Any:
        response = self.request(method, path, **kwargs)
        try:
            return response.json()
        except (ValueError, UnicodeDecodeError):
            raise MalformedResponseError("a JSON body", response.text[:300], **self.context_for(path)) from None

    def stream_lines(self, method: str, path: str, **kwargs: Any) -> Iterator[str]:
        """Yield the response body line by line (for SSE and NDJSON), errors typed."""
        with self._mapped(path), self.client.stream(method, path, **kwargs) as response:
            if response.status_code >= 400:
                response.read()
                self._check_status(response, path)
            yield from response.iter_lines()

    def stream_text(self, method: str, path: str, **kwargs: Any) -> Iterator[str]:
        """Yield decoded text pieces as they arrive (RoboML streams plain text)."""
        with self._mapped(path), self.client.stream(method, path, **kwargs) as response:
            if response.status_code >= 400:
                response.read()
                self._check_status(response, path)
            yield from response.iter_text()

    def json_lines(self, lines: Iterator[str], path: str) -> Iterator[dict]:
        """Parse NDJSON, one object per non-empty line."""
        for line in lines:
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except ValueError:
                raise MalformedResponseError("an NDJSON line holding a JSON object", line, **self.context_for(path)) from None
            if not isinstance(obj, dict):
                raise MalformedResponseError("an NDJSON line holding a JSON object", line, **self.context_for(path))
            yield obj
