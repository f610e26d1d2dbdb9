"""How much the model server holds for its clients: sizes per request and one budget for all.

Every size a peer announces (an HTTP ``Content-Length``, a RESP bulk string or array header) is
checked before anything is allocated for it, and the bytes of requests being received or served
count against one :class:`ByteBudget` shared by the HTTP and RESP listeners, so many connections
together cannot grow the server past it either.
"""
from __future__ import annotations

import threading

__all__ = ["ByteBudget", "MiB", "MAX_HTTP_BODY", "MAX_WS_MESSAGE", "MAX_IN_FLIGHT", "MAX_RESP_BULK",
           "MAX_RESP_ELEMENTS", "MAX_RESP_COMMAND", "MAX_RESP_CONNECTIONS", "MAX_EMBED_INPUTS", "MAX_EMBED_CHARS",
           "MAX_JSON_DEPTH", "MAX_MSGPACK_ITEMS", "unpack_msgpack"]

MiB = 1024 * 1024
#: one HTTP request body (aiohttp's ``client_max_size``): a base64 image or a WAV upload fits.
MAX_HTTP_BODY = 32 * MiB
#: one WebSocket message (RoboML's ws_inference: msgpack with images or audio).
MAX_WS_MESSAGE = 32 * MiB
#: request bytes held at once by all HTTP requests and RESP commands together.
MAX_IN_FLIGHT = 256 * MiB
#: RESP: one bulk string, the arguments of one command, and the bulk strings summed per command.
MAX_RESP_BULK = 64 * MiB
MAX_RESP_ELEMENTS = 1024
MAX_RESP_COMMAND = 64 * MiB
#: RESP connections served at once; more are answered with an error and closed.
MAX_RESP_CONNECTIONS = 128
#: embeddings: texts per request (OpenAI's own limit) and their total length in characters.
MAX_EMBED_INPUTS = 2048
MAX_EMBED_CHARS = 1_000_000
#: msgpack payloads (RESP arguments, WebSocket frames): elements per array or map, so a small
#: payload cannot unpack into a huge list (one byte per nil, eight per list slot)
MAX_MSGPACK_ITEMS = 100_000
#: JSON bodies nested deeper than this are refused (the codecs and json.dumps recurse).
MAX_JSON_DEPTH = 64


def unpack_msgpack(data: bytes) -> object:
    """A peer's msgpack payload with bounded arrays and maps (ValueError beyond them)."""
    import msgpack

    return msgpack.unpackb(data, raw=False, max_array_len=MAX_MSGPACK_ITEMS, max_map_len=MAX_MSGPACK_ITEMS)


class ByteBudget:
    """A count of bytes in flight with a ceiling: take before allocating, give back after.

    Thread-safe (handlers run model calls in worker threads), though callers here are all on
    the event loop.
    """

    def __init__(self, limit: int = MAX_IN_FLIGHT) -> None:
        self.limit = limit
        self.in_use = 0
        self._lock = threading.Lock()

    def take(self, n: int) -> bool:
        """Reserve ``n`` bytes; False (and nothing reserved) if that would pass the limit."""
        with self._lock:
            if self.in_use + n > self.limit:
                return False
            self.in_use += n
            return True

    def give(self, n: int) -> None:
        with self._lock:
            self.in_use = max(0, self.in_use - n)

    def describe(self) -> str:
        return f"{self.in_use / MiB:.0f} MiB of {self.limit / MiB:.0f} MiB in flight"
