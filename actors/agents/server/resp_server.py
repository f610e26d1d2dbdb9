"""RoboML's RESP (Redis protocol) interface: ``PING``, ``add_node``, ``remove_node``,
``<node>.initialize``, ``<node>.get_status`` and ``<node>.inference``, msgpack payloads."""
from __future__ import annotations

import asyncio
import logging
from typing import Any

import msgpack

from ..clients.resp import ProtocolError, encode_reply
from .common import in_thread
from .roboml_nodes import NodeError, RoboMLNodes

__all__ = ["start_resp_server"]

log = logging.getLogger("emos.agents.server.resp")
MAX_ARGS = 64
MAX_ARG_BYTES = 256 * 1024 * 1024


async def _read_command(reader: asyncio.StreamReader) -> list[bytes]:
    line = await reader.readuntil(b"\r\n")
    if not line.startswith(b"*"):  # inline command, as redis-cli sends for PING
        return line[:-2].split()
    try:
        count = int(line[1:-2])
    except ValueError:
        raise ProtocolError(f"bad array header {line[:40]!r}") from None
    if not 0 < count <= MAX_ARGS:
        raise ProtocolError(f"command with {count} arguments")
    args = []
    for _ in range(count):
        header = await reader.readuntil(b"\r\n")
        if not header.startswith(b"$"):
            raise ProtocolError(f"expected a bulk string, got {header[:40]!r}")
        size = int(header[1:-2])
        if not 0 <= size <= MAX_ARG_BYTES:
            raise ProtocolError(f"bulk string of {size} bytes")
        data = await reader.readexactly(size + 2)
        args.append(data[:-2])
    return args


def _unpack(args: list[bytes], index: int) -> Any:
    if len(args) <= index:
        return None
    try:
        return msgpack.unpackb(args[index], raw=False)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
        raise NodeError(400, "argument is not msgpack") from None


async def _dispatch(nodes: RoboMLNodes, args: list[bytes]) -> bytes:
    if not args:
        raise NodeError(400, "empty command")
    command = args[0].decode(errors="replace")
    lower = command.lower()
    if lower == "ping":
        return b"+PONG\r\n"
    if lower == "add_node":
        params = _unpack(args, 1) or {}
        _status, body = nodes.add_node(str(params.get("node_name", "")), str(params.get("node_model", "")))
        return encode_reply(msgpack.packb(body))
    if lower == "remove_node":
        params = _unpack(args, 1) or {}
        return encode_reply(msgpack.packb(nodes.remove_node(str(params.get("node_name", "")))))
    name, _, method = command.rpartition(".")
    if method == "initialize":
        nodes.initialize(name, _unpack(args, 1))
        return b"+OK\r\n"
    if method == "get_status":
        return encode_reply(msgpack.packb(nodes.status(name)))
    if method == "inference":
        data = _unpack(args, 1)
        if isinstance(data, dict):
            data.pop("stream", None)  # RESP replies are not streamed
        result = await in_thread(nodes.inference, name, data)
        return encode_reply(msgpack.packb(result))
    raise NodeError(400, f"unknown command {command!r}")


class RespServer:
    """The RESP listener plus its live connections, so shutdown can end them cleanly."""

    def __init__(self, nodes: RoboMLNodes) -> None:
        self.nodes = nodes
        self.server: asyncio.base_events.Server | None = None
        self.connections: set[asyncio.Task] = set()
        self.writers: set[asyncio.StreamWriter] = set()

    @property
    def port(self) -> int:
        return self.server.sockets[0].getsockname()[1]

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        self.connections.add(task)
        self.writers.add(writer)
        try:
            while True:
                try:
                    args = await _read_command(reader)
                except (asyncio.IncompleteReadError, ConnectionError):
                    break
                except (ProtocolError, ValueError, asyncio.LimitOverrunError) as exc:
                    writer.write(encode_reply(ProtocolError(f"protocol error: {exc}")))
                    break
                try:
                    reply = await _dispatch(self.nodes, args)
                except NodeError as exc:
                    reply = encode_reply(exc)
                writer.write(reply)
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            self.connections.discard(task)
            self.writers.discard(writer)
            writer.close()

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
        for writer in list(self.writers):
            writer.close()  # the handler's pending read then ends with IncompleteReadError
        if self.connections:
            await asyncio.wait(list(self.connections), timeout=2.0)


async def start_resp_server(nodes: RoboMLNodes, host: str, port: int) -> RespServer:
    resp = RespServer(nodes)
    resp.server = await asyncio.start_server(resp.handle, host, port, limit=1024 * 1024)
    return resp
