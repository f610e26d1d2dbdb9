"""RoboML's RESP (Redis protocol) interface: ``PING``, ``add_node``, ``remove_node``,
``<node>.initialize``, ``<node>.get_status`` and ``<node>.inference``, msgpack payloads."""
from __future__ import annotations

import asyncio
import logging
from typing import Any

import msgpack

from emos.errors import EmosError
from emos.ratelimit import RateLimitedLog

from ..clients.resp import ProtocolError, encode_reply
from .common import in_thread
from .limits import (
    MAX_MSGPACK_ITEMS,
    MAX_RESP_BULK,
    MAX_RESP_COMMAND,
    MAX_RESP_CONNECTIONS,
    MAX_RESP_ELEMENTS,
    ByteBudget,
    MiB,
    unpack_msgpack,
)
from .roboml_nodes import NodeError, RoboMLNodes

__all__ = ["start_resp_server", "RespServer"]

log = logging.getLogger("emos.agents.server.resp")
_warn = RateLimitedLog(log, interval=10.0)
#: bytes read per step of a bulk string: memory grows with what arrived, not what was announced
CHUNK = 256 * 1024
#: a command that has started must keep arriving: a peer that stalls mid-command holds budget
STALL_S = 60.0
#: the stream's buffer limit: a header or inline command longer than this is a protocol error,
#: and reading pauses once twice this much is buffered
LINE_LIMIT = 1024 * 1024


class Busy(EmosError):
    """The server-wide byte budget is spent: the command is refused and the connection closed."""


class Command:
    """One command being read: its arguments and the budget they hold until it is answered."""

    def __init__(self, budget: ByteBudget) -> None:
        self.budget = budget
        self.held = 0

    def take(self, n: int) -> None:
        if not self.budget.take(n):
            raise Busy(f"server busy: {self.budget.describe()}")
        self.held += n

    def release(self) -> None:
        self.budget.give(self.held)
        self.held = 0


async def _read_bulk(reader: asyncio.StreamReader, size: int, command: Command) -> bytearray:
    data = bytearray()
    while len(data) < size:
        step = min(CHUNK, size - len(data))
        command.take(step)  # before reading: the budget bounds what is buffered
        data += await asyncio.wait_for(reader.readexactly(step), STALL_S)
    if await asyncio.wait_for(reader.readexactly(2), STALL_S) != b"\r\n":
        raise ProtocolError("bulk string not terminated by CRLF")
    return data


async def _read_command(reader: asyncio.StreamReader, command: Command) -> list[Any]:
    """One command's arguments. Every announced size is checked before anything is allocated
    for it: at most MAX_RESP_ELEMENTS arguments, MAX_RESP_BULK bytes each and MAX_RESP_COMMAND
    bytes together; the bytes read are held in ``command`` against the server's budget."""
    line = await reader.readuntil(b"\r\n")  # waits for the next command: no stall limit here
    if not line.startswith(b"*"):  # inline command, as redis-cli sends for PING
        words = line[:-2].split()
        # Nothing else may be inline: a web page can POST to this port, and the lines of its
        # HTTP request ("POST / HTTP/1.1", headers, a body of RESP commands) must not run as
        # commands (the cross-protocol attack Redis also closes the connection for).
        if words and words[0].upper() != b"PING":
            raise ProtocolError(f"inline command {line[:40]!r}: only PING may be sent inline "
                                "(an HTTP request on the RESP port?)")
        return words
    try:
        count = int(line[1:-2])
    except ValueError:
        raise ProtocolError(f"bad array header {line[:40]!r}") from None
    if not 0 < count <= MAX_RESP_ELEMENTS:
        raise ProtocolError(f"command with {count} arguments (at most {MAX_RESP_ELEMENTS})")
    args: list[Any] = []
    total = 0
    for _ in range(count):
        header = await asyncio.wait_for(reader.readuntil(b"\r\n"), STALL_S)
        if not header.startswith(b"$"):
            raise ProtocolError(f"expected a bulk string, got {header[:40]!r}")
        try:
            size = int(header[1:-2])
        except ValueError:
            raise ProtocolError(f"bad bulk string header {header[:40]!r}") from None
        if not 0 <= size <= MAX_RESP_BULK:
            raise ProtocolError(f"bulk string of {size} bytes (at most {MAX_RESP_BULK // MiB} MiB)")
        total += size
        if total > MAX_RESP_COMMAND:
            raise ProtocolError(f"command of more than {MAX_RESP_COMMAND // MiB} MiB")
        args.append(await _read_bulk(reader, size, command))
    return args


def _unpack(args: list[Any], index: int) -> Any:
    if len(args) <= index:
        return None
    try:
        return unpack_msgpack(args[index])
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as exc:
        raise NodeError(400, f"argument is not msgpack, or holds more than {MAX_MSGPACK_ITEMS} items "
                             f"in one array or map ({type(exc).__name__})") from None


def _params(args: list[Any]) -> dict:
    params = _unpack(args, 1) or {}
    if not isinstance(params, dict):
        raise NodeError(400, f"expected a msgpack map of parameters, got {type(params).__name__}")
    return params


async def _dispatch(nodes: RoboMLNodes, args: list[Any]) -> bytes:
    if not args:
        raise NodeError(400, "empty command")
    command = bytes(args[0]).decode(errors="replace")
    lower = command.lower()
    if lower == "ping":
        return b"+PONG\r\n"
    if lower == "add_node":
        params = _params(args)
        _status, body = nodes.add_node(str(params.get("node_name", "")), str(params.get("node_model", "")))
        return encode_reply(msgpack.packb(body))
    if lower == "remove_node":
        params = _params(args)
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
    """The RESP listener plus its live connections, so shutdown can end them cleanly. Its
    commands hold their bytes against ``budget``, which the HTTP side shares."""

    def __init__(self, nodes: RoboMLNodes, budget: ByteBudget | None = None) -> None:
        self.nodes = nodes
        self.budget = budget or ByteBudget()
        self.server: asyncio.base_events.Server | None = None
        self.connections: set[asyncio.Task] = set()
        self.writers: set[asyncio.StreamWriter] = set()

    @property
    def port(self) -> int:
        if self.server is None:
            raise RuntimeError("RESP server: not listening, so it has no port yet")
        return self.server.sockets[0].getsockname()[1]

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        address = writer.get_extra_info("peername")
        peer = f"{address[0]}:{address[1]}" if isinstance(address, tuple) else str(address)
        who = str(address[0]) if isinstance(address, tuple) else peer  # rate-limit per host, not per connection
        if len(self.connections) >= MAX_RESP_CONNECTIONS:
            _warn.warning("connections", "RESP port %s: refused %s: %d connections already open",
                          self.port, peer, len(self.connections))
            writer.write(encode_reply(RuntimeError(f"server busy: {MAX_RESP_CONNECTIONS} connections open")))
            writer.close()
            return
        task = asyncio.current_task()
        assert task is not None  # the server runs each connection's handler as a task
        self.connections.add(task)
        self.writers.add(writer)
        command = Command(self.budget)
        try:
            while True:
                try:
                    args = await _read_command(reader, command)
                except (asyncio.IncompleteReadError, ConnectionError):
                    break
                except Busy as exc:
                    _warn.warning(f"busy:{who}", "RESP port %s: closed the connection of %s: %s", self.port, peer, exc)
                    writer.write(encode_reply(exc))
                    break
                except TimeoutError:
                    _warn.warning(f"stall:{who}", "RESP port %s: closed the connection of %s: a command stalled "
                                  "for %.0f s", self.port, peer, STALL_S)
                    break
                except (ProtocolError, ValueError, asyncio.LimitOverrunError) as exc:
                    _warn.warning(f"protocol:{who}", "RESP port %s: closed the connection of %s: %s", self.port, peer, exc)
                    writer.write(encode_reply(ProtocolError(f"protocol error: {exc}")))
                    break
                try:
                    reply = await _dispatch(self.nodes, args)
                except NodeError as exc:
                    reply = encode_reply(exc)
                except RecursionError:
                    reply = encode_reply(NodeError(400, "argument is nested too deeply"))
                except Exception as exc:  # a bug, not the peer's fault: one error reply, details in the log
                    log.exception("RESP port %s: command from %s failed", self.port, peer)
                    reply = encode_reply(RuntimeError(f"internal error in the model server ({type(exc).__name__})"))
                finally:
                    del args
                    command.release()
                writer.write(reply)
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            command.release()
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


async def start_resp_server(nodes: RoboMLNodes, host: str, port: int, budget: ByteBudget | None = None) -> RespServer:
    resp = RespServer(nodes, budget)
    resp.server = await asyncio.start_server(resp.handle, host, port, limit=LINE_LIMIT)
    return resp
