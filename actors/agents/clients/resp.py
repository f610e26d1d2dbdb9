"""RESP2 (the Redis serialization protocol), both directions, over blocking or asyncio streams.

RoboML's RESP server speaks it: commands are arrays of bulk strings, replies are simple
strings (``+``), errors (``-``), integers (``:``), bulk strings (``$``) or arrays (``*``).
Reference: https://redis.io/docs/latest/develop/reference/protocol-spec/
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from emos.errors import EmosError

__all__ = ["encode_command", "encode_reply", "read_reply", "RespError", "ProtocolError", "MAX_BULK"]

#: largest bulk string we accept (Redis' own limit is 512 MB; images fit well below this).
MAX_BULK = 256 * 1024 * 1024


class RespError(EmosError):
    """An error reply (``-ERR ...``) from the server."""


class ProtocolError(EmosError, ValueError):
    """Bytes that are not RESP."""


def _bulk(value: bytes | str | int | float) -> bytes:
    if isinstance(value, str):
        value = value.encode()
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        value = str(value).encode()
    if not isinstance(value, (bytes, bytearray)):
        raise TypeError(f"RESP command arguments must be bytes, str or numbers, got {type(value).__name__}")
    return b"$%d\r\n%s\r\n" % (len(value), bytes(value))


def encode_command(*args: bytes | str | int | float) -> bytes:
    """A client command: an array of bulk strings."""
    return b"*%d\r\n" % len(args) + b"".join(_bulk(a) for a in args)


def encode_reply(value: Any) -> bytes:
    """A server reply. ``None`` is the null bulk string; exceptions become error replies."""
    if value is None:
        return b"$-1\r\n"
    if isinstance(value, BaseException):
        text = str(value).replace("\r", " ").replace("\n", " ")
        return b"-ERR " + text.encode() + b"\r\n"
    if isinstance(value, bool):
        return b":%d\r\n" % int(value)
    if isinstance(value, int):
        return b":%d\r\n" % value
    if isinstance(value, (list, tuple)):
        return b"*%d\r\n" % len(value) + b"".join(encode_reply(v) for v in value)
    return _bulk(value)


def read_reply(readline: Callable[[], bytes], readexactly: Callable[[int], bytes]) -> Any:
    """Parse one reply with the given blocking readers (``readline`` returns up to ``\\r\\n``).

    Error replies are returned as :class:`RespError` instances (not raised) so callers decide.
    """
    line = readline()
    if not line:
        raise EOFError("connection closed before a RESP reply")
    if not line.endswith(b"\r\n"):
        raise ProtocolError(f"RESP line without CRLF: {line[:60]!r}")
    kind, rest = line[:1], line[1:-2]
    if kind == b"+":
        return rest.decode(errors="replace")
    if kind == b"-":
        return RespError(rest.decode(errors="replace"))
    if kind == b":":
        try:
            return int(rest)
        except ValueError:
            raise ProtocolError(f"bad RESP integer {rest[:60]!r}") from None
    if kind in (b"$", b"*"):
        try:
            size = int(rest)
        except ValueError:
            raise ProtocolError(f"bad RESP length {rest[:60]!r}") from None
        if size < 0:
            return None
        if kind == b"$":
            if size > MAX_BULK:
                raise ProtocolError(f"RESP bulk string of {size} bytes exceeds the {MAX_BULK} byte limit")
            data = readexactly(size + 2)
            if data[-2:] != b"\r\n":
                raise ProtocolError("RESP bulk string not terminated by CRLF")
            return data[:-2]
        return [read_reply(readline, readexactly) for _ in range(size)]
    raise ProtocolError(f"unknown RESP type byte {kind!r} in {line[:60]!r}")
