"""Request/response and streaming over Unix stream sockets: msgpack frames, never pickle.

Frame: ``u32 length | msgpack map``. A request is ``{"id": n, "op": str, ...}``; its answer is
``{"id": n, "ok": true, "result": ...}`` or ``{"id": n, "ok": false, "error": str}``. A handler
may stream ``{"id": n, "stream": ...}`` frames before the answer (action feedback). Sockets are
created with mode 0600 inside the run's 0700 directory: only the user running the system can
connect. Message payloads travel as ``bin`` (the topic frame format), decoded by the receiver into
the type it expects, so nothing that arrives can make us construct arbitrary objects.
"""
from __future__ import annotations

import asyncio
import itertools
import logging
import os
import socket
import struct
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import msgpack

from emos.core.retry import Backoff
from emos.errors import EmosError, TransportError

log = logging.getLogger("emos.rpc")

_LEN = struct.Struct("<I")
# What one frame may hold. The length prefix is read first and the body buffered whole, so the
# bound is what a peer can make us allocate. Services and actions carry messages (a map, an
# image) and get MAX_FRAME; control sockets carry small maps (lifecycle, parameters, the tree)
# and are built with CONTROL_FRAME. Bigger payloads belong on topics (shared memory).
MAX_FRAME = 64 << 20
CONTROL_FRAME = 1 << 20

Handler = Callable[[dict[str, Any], "StreamWriter"], Awaitable[Any]]


class RpcError(EmosError, RuntimeError):
    """The remote side answered with an error."""


class RpcConnectionError(TransportError, ConnectionError):
    """No connection, or the connection broke before an answer came."""


class RpcUnreachable(RpcConnectionError):
    """Nothing listens at the socket (its server not started yet, or restarting). The request was
    never sent, so trying again cannot run it twice."""


# Retrying a server that does not listen: soon at first, then at most five times a second, until
# the caller's timeout (``attrs.evolve(UNREACHABLE_BACKOFF, timeout=...)``).
UNREACHABLE_BACKOFF = Backoff(base=0.01, factor=2.0, cap=0.2, timeout=0.0)


def pack_frame(obj: Any) -> bytes:
    body = msgpack.packb(obj, use_bin_type=True)
    return _LEN.pack(len(body)) + body


def _unpack(body: bytes) -> Any:
    return msgpack.unpackb(body, raw=False, strict_map_key=False)


class FrameTooLarge(RpcConnectionError):
    """A peer announced a frame above the limit; the connection cannot be resynchronised."""


async def read_frame(reader: asyncio.StreamReader, limit: int = MAX_FRAME) -> Any:
    head = await reader.readexactly(4)
    (n,) = _LEN.unpack(head)
    if n > limit:
        raise FrameTooLarge(f"frame of {n} B exceeds the limit of {limit} B")
    return _unpack(await reader.readexactly(n))


class StreamWriter:
    """Lets a handler stream intermediate frames for the request it serves."""

    def __init__(self, writer: asyncio.StreamWriter, request_id: Any):
        self._writer = writer
        self._id = request_id

    async def send(self, payload: Any) -> None:
        self._writer.write(pack_frame({"id": self._id, "stream": payload}))
        await self._writer.drain()


class RpcServer:
    """Serves ops on a Unix socket; ``handlers[op](request, stream)`` returns the result."""

    def __init__(self, path: Path, handlers: dict[str, Handler], name: str = "rpc", max_frame: int = MAX_FRAME):
        self.path = Path(path)
        self.max_frame = max_frame
        self.handlers = handlers
        self.name = name
        self._server: asyncio.base_events.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()  # requests being answered (_answer)
        self._connections: set[asyncio.Task[Any]] = set()  # the tasks serving each connection

    async def start(self) -> None:
        # Bind under a temporary name and rename once listening: whoever sees the socket file
        # can connect (between bind and listen a connect is refused).
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        if len(os.fsencode(str(tmp))) > 107:  # sun_path: 108 bytes with the NUL
            raise ValueError(f"{self.name}: socket path {tmp} is {len(os.fsencode(str(tmp)))} bytes; AF_UNIX allows 107 (use a shorter name)")
        for stale in (tmp, self.path):
            if stale.exists() or stale.is_symlink():
                stale.unlink()
        old = os.umask(0o177)  # the socket file is created 0600, with no window at a wider mode
        try:
            self._server = await asyncio.start_unix_server(self._serve, path=str(tmp))
        finally:
            os.umask(old)
        os.rename(tmp, self.path)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        me = asyncio.current_task()
        if me is not None:
            self._connections.add(me)
        try:
            while True:
                try:
                    req = await read_frame(reader, self.max_frame)
                except FrameTooLarge as exc:
                    log.warning("%s: %s; closing the connection", self.name, exc)
                    writer.write(pack_frame({"id": None, "ok": False, "error": f"{self.name}: request {exc}; connection closed"}))
                    return
                except (asyncio.IncompleteReadError, ConnectionError):
                    return
                except (ValueError, TypeError, msgpack.ExtraData) as exc:  # not msgpack at all
                    writer.write(pack_frame({"id": None, "ok": False, "error": f"malformed request: {exc}"}))
                    continue
                if not isinstance(req, dict) or not isinstance(req.get("op"), str):
                    op = req.get("op") if isinstance(req, dict) else None
                    rid = req.get("id") if isinstance(req, dict) else None
                    writer.write(pack_frame({
                        "id": rid if isinstance(rid, (int, str, type(None))) else None, "ok": False,
                        "error": f"malformed request: expected a map with a string 'op', got op={op!r}",
                    }))
                    continue
                task = asyncio.ensure_future(self._answer(req, writer))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)
        except asyncio.CancelledError:
            pass
        finally:
            if me is not None:
                self._connections.discard(me)
            writer.close()

    async def _answer(self, req: dict[str, Any], writer: asyncio.StreamWriter) -> None:
        rid = req.get("id")
        handler = self.handlers.get(req["op"])
        if handler is None:
            reply = {"id": rid, "ok": False, "error": f"{self.name}: unknown op {req['op']!r}; known: {sorted(self.handlers)}"}
        else:
            try:
                reply = {"id": rid, "ok": True, "result": await handler(req, StreamWriter(writer, rid))}
            except Exception as exc:  # reported to the caller, and logged here with the op named
                log.warning("%s: op %r failed: %s", self.name, req["op"], exc)
                reply = {"id": rid, "ok": False, "error": f"{type(exc).__name__}: {exc}"}
        try:
            writer.write(pack_frame(reply))
            await writer.drain()
        except (ConnectionError, RuntimeError):
            pass  # the caller went away; nothing to answer

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            pending = list(self._tasks) + list(self._connections)
            for task in pending:
                task.cancel()
            if pending:
                await asyncio.gather(*pending, return_exceptions=True)
            self._server = None
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass


class RpcClient:
    """Blocking client, for the CLI, tests and code outside an event loop."""

    def __init__(self, path: Path | str, timeout: float = 5.0):
        self.path = str(path)
        self.timeout = timeout
        self._ids = itertools.count(1)
        self._sock: socket.socket | None = None

    def _connect(self) -> socket.socket:
        if self._sock is None:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.settimeout(self.timeout)
            try:
                sock.connect(self.path)
            except OSError as exc:
                sock.close()
                raise RpcUnreachable(f"cannot connect to {self.path}: {exc.strerror or exc}") from exc
            self._sock = sock
        return self._sock

    def _recv_exact(self, n: int) -> bytes:
        assert self._sock is not None
        chunks, got = [], 0
        while got < n:
            chunk = self._sock.recv(min(n - got, 1 << 20))
            if not chunk:
                raise RpcConnectionError(f"{self.path}: connection closed before the answer")
            chunks.append(chunk)
            got += len(chunk)
        return b"".join(chunks)

    def call(self, op: str, on_stream: Callable[[Any], None] | None = None, timeout: float | None = None, **payload: Any) -> Any:
        sock = self._connect()
        if timeout is not None:
            sock.settimeout(timeout)
        rid = next(self._ids)
        try:
            sock.sendall(pack_frame({"id": rid, "op": op, **payload}))
            while True:
                (n,) = _LEN.unpack(self._recv_exact(4))
                frame = _unpack(self._recv_exact(n))
                if frame.get("id") != rid:
                    continue
                if "stream" in frame:
                    if on_stream is not None:
                        on_stream(frame["stream"])
                    continue
                if frame.get("ok"):
                    return frame.get("result")
                raise RpcError(frame.get("error", "unknown error"))
        except TimeoutError as exc:
            self.close()
            raise TimeoutError(f"{self.path}: no answer to {op!r} within {sock.gettimeout()} s") from exc
        except OSError as exc:
            self.close()
            raise RpcConnectionError(f"{self.path}: {op!r} failed: {exc}") from exc
        finally:
            if timeout is not None and self._sock is not None:
                self._sock.settimeout(self.timeout)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> RpcClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AsyncRpcClient:
    """Client for use inside an event loop; many requests may be in flight on one connection."""

    def __init__(self, path: Path | str):
        self.path = str(path)
        self._ids = itertools.count(1)
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._pending: dict[int, tuple[asyncio.Future[Any], Callable[[Any], None] | None]] = {}
        self._pump: asyncio.Task[None] | None = None

    async def connect(self) -> None:
        try:
            self._reader, self._writer = await asyncio.open_unix_connection(self.path)
        except OSError as exc:
            raise RpcUnreachable(f"cannot connect to {self.path}: {exc.strerror or exc}") from exc
        self._pump = asyncio.ensure_future(self._read_loop())

    async def _read_loop(self) -> None:
        assert self._reader is not None
        try:
            while True:
                frame = await read_frame(self._reader)
                entry = self._pending.get(frame.get("id"))
                if entry is None:
                    continue
                fut, on_stream = entry
                if "stream" in frame:
                    if on_stream is not None:
                        on_stream(frame["stream"])
                elif not fut.done():
                    if frame.get("ok"):
                        fut.set_result(frame.get("result"))
                    else:
                        fut.set_exception(RpcError(frame.get("error", "unknown error")))
        except (asyncio.IncompleteReadError, ConnectionError, OSError) as exc:
            err = RpcConnectionError(f"{self.path}: connection lost ({exc.__class__.__name__})")
        except asyncio.CancelledError:
            err = RpcConnectionError(f"{self.path}: client closed")
        for fut, _ in self._pending.values():
            if not fut.done():
                fut.set_exception(err)
        self._pending.clear()

    async def call(self, op: str, timeout: float | None = 10.0, on_stream: Callable[[Any], None] | None = None, **payload: Any) -> Any:
        if self._writer is None:
            await self.connect()
        assert self._writer is not None
        rid = next(self._ids)
        fut: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._pending[rid] = (fut, on_stream)
        try:
            self._writer.write(pack_frame({"id": rid, "op": op, **payload}))
            await self._writer.drain()
            return await asyncio.wait_for(fut, timeout)
        except TimeoutError:
            raise TimeoutError(f"{self.path}: no answer to {op!r} within {timeout} s") from None
        except (ConnectionError, OSError) as exc:
            raise RpcConnectionError(f"{self.path}: {op!r} failed: {exc}") from exc
        finally:
            self._pending.pop(rid, None)

    async def close(self) -> None:
        if self._pump is not None:
            self._pump.cancel()
            self._pump = None
        if self._writer is not None:
            self._writer.close()
            self._writer = None
