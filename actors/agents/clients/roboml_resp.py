"""RoboMLRESPClient: RoboML over the Redis serialization protocol (RESP), msgpack payloads.

Commands: ``PING``, ``add_node``, ``<name>.initialize``, ``<name>.get_status``,
``<name>.inference``, ``remove_node``; each payload is one msgpack bulk string. RESP replies
are not streamed: a streaming chat request is answered in one piece. No redis package is
needed: RESP is small enough to speak directly over a socket.
"""
from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator
from typing import Any

import msgpack

from ..errors import MalformedResponseError, ModelConnectionError, ModelServerError, ModelTimeoutError
from ..types import ChatChunk, ChatRequest, DetectionRequest
from . import roboml_codec
from .base import ModelClient
from .resp import ProtocolError, RespError, encode_command, read_reply

__all__ = ["RoboMLRESPClient"]


class RoboMLRESPClient(ModelClient):
    SUPPORTED_MODELS = tuple(roboml_codec.MODEL_KINDS)
    DEFAULT_PORT = 6379

    def __init__(self, model, host: str = "127.0.0.1", port: int | None = 6379, inference_timeout: float = 30,
                 init_on_activation: bool = True, logging_level: str = "info", **kwargs: Any) -> None:
        super().__init__(model, host=host, port=port, inference_timeout=inference_timeout,
                         init_on_activation=init_on_activation, logging_level=logging_level, **kwargs)
        self._sock: socket.socket | None = None
        self._file: Any = None

    @property
    def url(self) -> str:
        return f"resp://{self.host}:{self.port}"

    def close(self) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._file.close()
                self._sock.close()
        self._sock = self._file = None

    def _connect(self) -> socket.socket:
        """The open connection (made on first use, or after close())."""
        if self._sock is None:
            sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock, self._file = sock, sock.makefile("rb")
        return self._sock

    def _readexactly(self, n: int) -> bytes:
        data = self._file.read(n)
        if len(data) != n:
            raise EOFError("connection closed in the middle of a RESP reply")
        return data

    def command(self, *args: Any, timeout: float | None = None) -> Any:
        """Send one command and return its decoded reply; failures are typed errors."""
        ctx = self._error_context()
        try:
            sock = self._connect()
            sock.settimeout(timeout or self.inference_timeout)
            sock.sendall(encode_command(*args))
            reply = read_reply(self._file.readline, self._readexactly)
        except TimeoutError:
            self.close()  # the late reply would be read as the next command's answer
            raise ModelTimeoutError("no RESP reply within the timeout", **ctx) from None
        except ProtocolError as exc:
            self.close()
            raise MalformedResponseError("a RESP reply", str(exc), **ctx) from None
        except EOFError as exc:
            self.close()
            raise ModelConnectionError(f"server closed the connection ({exc})", **ctx) from None
        except OSError as exc:
            self.close()
            raise ModelConnectionError(f"cannot connect ({exc})", **ctx) from None
        if isinstance(reply, RespError):
            raise ModelServerError(f"RESP error reply to {str(args[0])!r}", status=500, body=str(reply), **ctx)
        return reply

    def _unpack(self, reply: Any) -> Any:
        if not isinstance(reply, bytes):
            raise MalformedResponseError("a msgpack bulk string", reply, **self._error_context())
        try:
            return msgpack.unpackb(reply, raw=False)
        except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
            raise MalformedResponseError("a msgpack bulk string", reply[:60], **self._error_context()) from None

    # ------------------------------------------------------------------ lifecycle
    def _check_connection(self) -> None:
        reply = self.command("PING")
        if reply not in ("PONG", b"PONG"):
            raise MalformedResponseError("PONG", reply, **self._error_context())

    def _initialize(self) -> None:
        self.command("add_node", msgpack.packb({"node_name": self.model_name, "node_model": self.model_type}))
        self.command(f"{self.model_name}.initialize", msgpack.packb(self.model.get_init_params()),
                     timeout=self.init_timeout or max(self.inference_timeout, 600.0))
        status = self._unpack(self.command(f"{self.model_name}.get_status"))
        if status != "READY":
            raise ModelServerError(f"node {self.model_name!r} is {status} after initialization", status=500,
                                   **self._error_context())

    def _deinitialize(self) -> None:
        self.command("remove_node", msgpack.packb({"node_name": self.model_name}))

    # ------------------------------------------------------------------ inference
    def _run(self, request: Any) -> Any:
        ctx = self._error_context()
        kind = roboml_codec.kind_of(request, self.model_type, ctx)
        payload = roboml_codec.build_payload(request, kind, raw_bytes=True)
        payload.pop("stream", None)
        body = self._unpack(self.command(f"{self.model_name}.inference", msgpack.packb(payload, use_bin_type=True)))
        return roboml_codec.parse_output(body, kind, self.model.checkpoint, ctx)

    _chat = _speech = _transcribe = _run

    def _other_inference(self, request: Any) -> Any:
        if isinstance(request, DetectionRequest):
            return self._run(request)
        return super()._other_inference(request)

    def _chat_stream(self, request: ChatRequest) -> Iterator[ChatChunk]:
        # RESP has no streaming: deliver the whole reply as one chunk, then the done marker.
        response = self._retrying(lambda: self._run(request))

        def chunks() -> Iterator[ChatChunk]:
            if response.message.content:
                yield ChatChunk(content=response.message.content)
            yield ChatChunk(content="", done=True, finish_reason="stop")

        return chunks()
