"""RoboMLWSClient: low-latency inference over a persistent WebSocket (msgpack requests).

Node management (add, initialize, remove) goes over HTTP like RoboML's own client; inference
goes over ``ws://host:port/{name}/ws_inference``. A streamed reply is a run of text frames
ended by RoboML's terminator frame ``<<Response Ended>>``; other replies are one frame (text,
audio bytes, or msgpack for structured outputs).
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import msgpack

from ..errors import ErrorContext, MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError
from ..types import ChatChunk, ChatRequest
from . import roboml_codec
from .roboml import RoboMLHTTPClient

__all__ = ["RoboMLWSClient", "STREAM_END"]

STREAM_END = "<<Response Ended>>"


class RoboMLWSClient(RoboMLHTTPClient):
    """RoboML over WebSocket; the connection opens on first inference and is reused."""

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 8000, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        self._ws: Any = None

    @property
    def websocket_url(self) -> str:
        base = self.url.replace("https://", "wss://").replace("http://", "ws://")
        return f"{base}/{self.model_name}/ws_inference"

    def close(self) -> None:
        self._drop()
        super().close()

    def _drop(self) -> None:
        if self._ws is not None:
            with contextlib.suppress(Exception):
                self._ws.close()
            self._ws = None

    def _ctx(self) -> ErrorContext:
        return self._error_context(self.websocket_url)

    @contextlib.contextmanager
    def _mapped(self) -> Iterator[None]:
        """Map websockets/socket failures to typed errors; any failure drops the connection,
        since a half-read reply would otherwise be mistaken for the next request's answer."""
        from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

        try:
            yield
        except (ModelServerError, MalformedResponseError):
            self._drop()
            raise
        except TimeoutError:
            self._drop()
            raise ModelTimeoutError("no WebSocket reply within the timeout", **self._ctx()) from None
        except ConnectionClosed as exc:
            self._drop()
            code = exc.rcvd.code if exc.rcvd else 1006
            reason = exc.rcvd.reason if exc.rcvd else "connection lost"
            if code in (1000, 1001, 1006):
                raise ModelConnectionError(f"WebSocket closed ({code}: {reason})", **self._ctx()) from None
            raise ModelServerError("server closed the WebSocket with an error", status=code, body=reason, **self._ctx()) from None
        except InvalidStatus as exc:
            self._drop()
            raise ModelServerError("WebSocket upgrade refused", status=exc.response.status_code,
                                   body=exc.response.body.decode(errors="replace") if exc.response.body else "",
                                   **self._ctx()) from None
        except InvalidHandshake as exc:
            self._drop()
            raise MalformedResponseError("a WebSocket handshake", str(exc), **self._ctx()) from None
        except OSError as exc:
            self._drop()
            raise ModelConnectionError(f"cannot connect ({exc})", **self._ctx()) from None

    def _connection(self) -> Any:
        if self._ws is None:
            from websockets.sync.client import connect

            timeout, max_size = self.connect_timeout, 64 * 1024 * 1024
            try:  # websockets >= 15: a held (not context-managed) connection is "legacy" mode
                self._ws = connect(self.websocket_url, proxy=None, legacy=True, open_timeout=timeout, max_size=max_size, compression=None)
            except TypeError:  # older websockets: no proxy/legacy keywords, direct connection is the default
                self._ws = connect(self.websocket_url, open_timeout=timeout, max_size=max_size, compression=None)
        return self._ws

    def _send(self, payload: dict[str, Any]) -> Any:
        ws = self._connection()
        ws.send(msgpack.packb(payload, use_bin_type=True))
        return ws

    def _run(self, request: Any) -> Any:
        kind = roboml_codec.kind_of(request, self.model_type, self._ctx())
        with self._mapped():
            ws = self._send(roboml_codec.build_payload(request, kind, raw_bytes=True))
            frame = ws.recv(timeout=self.inference_timeout)
        if kind == "detect":
            if not isinstance(frame, bytes):
                raise MalformedResponseError("a msgpack frame of detections", frame, **self._ctx())
            try:
                frame = msgpack.unpackb(frame, raw=False)
            except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
                self._drop()
                raise MalformedResponseError("a msgpack frame of detections", frame[:60], **self._ctx()) from None
        return roboml_codec.parse_value(frame, kind, self.model.checkpoint, self._ctx())

    _chat = _speech = _transcribe = _run

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        kind = roboml_codec.kind_of(request, self.model_type, self._ctx())
        payload = roboml_codec.build_payload(request, kind, raw_bytes=True)

        def chunks() -> Iterator[ChatChunk]:
            with self._mapped():
                ws = self._send(payload)
                while True:
                    frame = ws.recv(timeout=self.inference_timeout)
                    if not isinstance(frame, str):
                        raise MalformedResponseError("streamed text frames", frame[:60], **self._ctx())
                    if frame == STREAM_END:
                        break
                    if frame:
                        yield ChatChunk(content=frame)
            yield ChatChunk(content="", done=True, finish_reason="stop")

        return chunks()
