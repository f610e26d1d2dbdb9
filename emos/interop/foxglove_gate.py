"""The gate in front of the Foxglove WebSocket server: Origin allow-list and optional token.

Why a gate of our own: foxglove-sdk 0.30's ``start_server`` has no hook that sees the HTTP
upgrade request (its ``ServerListener`` gets only a client id, after the handshake), accepts any
``Origin`` and has no authentication. Any web page open in a browser on the robot could then
connect to ``ws://127.0.0.1:8765`` and receive every topic, camera frames included. So the SDK
server listens on a private loopback address (a random one in 127.0.0.0/8, out of reach of a
browser page that scans ports), and :class:`HandshakeGate` listens where the user asked: it reads
the upgrade request, refuses it unless

* its ``Origin`` (sent by every browser) is on the allow-list (Foxglove's app, localhost pages);
  ``Origin: null`` (sandboxed frames, ``file:`` pages) is refused;
* a token is configured and the request carries it (``?token=...`` in the URL, the one way a
  browser page such as Foxglove can send it, or ``Authorization: Bearer ...``). A request without ``Origin``
  (not a browser) is let through only with the token, when there is one;

and then splices bytes between the client and the SDK server, untouched (the token removed from
the request line, so that it is in no log of the SDK).

Limit: a local user who reads /proc/net/tcp finds the SDK's private port and can connect to it
directly; the gate keeps out browsers and the network, not other accounts on the same machine.
"""
from __future__ import annotations

import asyncio
import hmac
import logging
import random
import re
import secrets
import threading
from collections.abc import Iterable
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

from emos.errors import EmosError
from emos.ratelimit import RateLimitedLog

log = logging.getLogger("emos.interop")
_refusals = RateLimitedLog(log)

#: Browser origins allowed by default: Foxglove's web app, and pages served from this machine
#: (Foxglove desktop and a self-hosted Foxglove use localhost origins).
DEFAULT_ORIGINS: tuple[str, ...] = (
    "https://app.foxglove.dev", "https://*.foxglove.dev",
    "http://localhost:*", "https://localhost:*", "http://127.0.0.1:*", "https://127.0.0.1:*",
    "http://[::1]:*", "https://[::1]:*",
)

MAX_HEAD = 16 * 1024          # an upgrade request is a few hundred bytes
HANDSHAKE_TIMEOUT_S = 10.0    # a client that opens a connection and says nothing is dropped
MAX_PENDING = 64              # connections still in their handshake at once
_SPLICE_CHUNK = 256 * 1024

# scheme://host[:port]; host a DNS name, an IPv4 address or a bracketed IPv6 address.
_ORIGIN = re.compile(r"(https?)://(\[[0-9a-f:.]+\]|[a-z0-9.-]+)(?::(\d{1,5}))?")
_PATTERN = re.compile(r"(https?)://(\*\.[a-z0-9.-]+|\[[0-9a-f:.]+\]|[a-z0-9.-]+)(?::(\d{1,5}|\*))?")


class OriginPattern:
    """``scheme://host[:port]`` where host may start with ``*.`` (any subdomain) and port may be
    ``*`` (any port, or none); or any other origin matched exactly (``file://``, ``null``), for a
    desktop app that loads its page from a file: only when asked for, as any local HTML file
    shares that origin."""

    __slots__ = ("scheme", "host", "port", "exact", "text")

    def __init__(self, text: str):
        norm = text.strip().lower()
        self.text = text
        self.exact: str | None = None
        m = _PATTERN.fullmatch(norm.rstrip("/"))
        if m is None:
            other_scheme = re.fullmatch(r"[a-z][a-z0-9+.-]*://\S*", norm) and not norm.startswith(("http://", "https://"))
            if norm == "null" or other_scheme:
                self.exact, self.scheme, self.host, self.port = norm, "", "", None
                return
            raise ValueError(f"allowed origin {text!r} is not scheme://host[:port] (host may start with '*.', port may be '*'), "
                             "e.g. https://app.foxglove.dev or http://localhost:*")
        self.scheme, self.host, self.port = m.group(1), m.group(2), m.group(3)

    def matches(self, origin: str) -> bool:
        if self.exact is not None:
            return origin.strip().lower() == self.exact
        m = _ORIGIN.fullmatch(origin.lower())
        if m is None:
            return False
        scheme, host, port = m.groups()
        if scheme != self.scheme:
            return False
        if self.host.startswith("*."):
            if not (host.endswith(self.host[1:]) and len(host) > len(self.host) - 1):
                return False
        elif host != self.host:
            return False
        return self.port == "*" or port == self.port


def make_token(token: str | None) -> str | None:
    """``"auto"``: a fresh random token; ``None``: no token; any other: itself, checked."""
    if token is None:
        return None
    if token == "auto":
        return secrets.token_urlsafe(24)
    if not isinstance(token, str) or len(token) < 8 or not re.fullmatch(r"[A-Za-z0-9._~-]+", token):
        raise ValueError("the Foxglove token must be 'auto' or at least 8 characters of A-Z a-z 0-9 . _ ~ - "
                         "(it goes into a URL), got " + ("a shorter or other string" if isinstance(token, str) else repr(token)))
    return token


def private_loopback_address() -> str:
    """A random address in 127.0.0.0/8 (Linux routes all of it to lo) for the SDK's server."""
    rng = random.SystemRandom()
    return f"127.{rng.randrange(256)}.{rng.randrange(256)}.{rng.randrange(2, 255)}"


class _Refused(EmosError):
    def __init__(self, status: str, reason: str):
        super().__init__(reason)
        self.status, self.reason = status, reason


class HandshakeGate:
    """Listens on ``host:port``; forwards accepted WebSocket handshakes to ``upstream``."""

    def __init__(self, host: str, port: int, upstream: tuple[str, int], allow_origins: Iterable[str] = (),
                 token: str | None = None, name: str = "Foxglove bridge"):
        self.patterns = [OriginPattern(p) for p in (*DEFAULT_ORIGINS, *allow_origins)]
        self.token = token
        self.upstream = upstream
        self.name = name
        self.refused = 0
        self.accepted = 0
        self._pending = 0
        self.host = host
        self._tasks: set[asyncio.Task[None]] = set()
        self._writers: set[asyncio.StreamWriter] = set()
        # Its own loop in its own thread: the caller (a component) may already run an event loop.
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="foxglove-gate", daemon=True)
        self._thread.start()
        try:
            self._server = asyncio.run_coroutine_threadsafe(
                asyncio.start_server(self._client, host, port, limit=MAX_HEAD), self._loop).result(timeout=30)
        except BaseException:
            self._stop_loop()
            raise
        self.port: int = self._server.sockets[0].getsockname()[1]

    # ------------------------------------------------------------------ checks
    def origin_allowed(self, origin: str) -> bool:
        return any(p.matches(origin) for p in self.patterns)

    def check(self, target: str, headers: dict[str, list[str]]) -> str:
        """The request target to forward (token removed), or :class:`_Refused`."""
        origins = headers.get("origin", [])
        if len(origins) > 1:
            raise _Refused("400 Bad Request", "more than one Origin header")
        origin = origins[0] if origins else None
        if origin is not None and not self.origin_allowed(origin):
            raise _Refused("403 Forbidden", f"origin {origin!r} is not allowed (see --allow-origin)")
        parts = urlsplit(target)
        query = parse_qsl(parts.query, keep_blank_values=True)
        given = [v for k, v in query if k == "token"]
        for value in headers.get("authorization", []):
            scheme, _, cred = value.partition(" ")
            if scheme.lower() == "bearer":
                given.append(cred.strip())
        if self.token is not None and not any(hmac.compare_digest(g.encode(), self.token.encode()) for g in given):
            raise _Refused("401 Unauthorized", "missing or wrong token" + ("" if origin else " (no Origin: not a browser)"))
        rest = [(k, v) for k, v in query if k != "token"]
        return urlunsplit(("", "", parts.path or "/", urlencode(rest), ""))

    # ------------------------------------------------------------------ connections
    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        self._writers.add(writer)
        try:
            await self._serve(reader, writer)
        finally:
            writer.close()
            self._writers.discard(writer)
            self._tasks.discard(task)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        try:
            head = await self._read_head(reader)
            method, target, version, headers = _parse_head(head)
            if method != "GET":
                raise _Refused("405 Method Not Allowed", f"method {method!r}")
            forward_target = self.check(target, headers)
        except _Refused as exc:
            self.refused += 1
            # Keyed by status, not by the (client-chosen) origin: a flood of made-up origins stays one line per interval.
            _refusals.warning(f"{self.name}:{self.port}:{exc.status}", "%s on port %d: refused a connection from %s: %s",
                              self.name, self.port, _peer(peer), exc.reason)
            await _reply(writer, exc.status, exc.reason)
            return
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        except OSError as exc:
            log.error("%s on port %d: the Foxglove server at %s:%d is not reachable: %s", self.name, self.port, *self.upstream, exc)
            await _reply(writer, "502 Bad Gateway", "the Foxglove server is not reachable")
            return
        self.accepted += 1
        self._writers.add(up_writer)
        # The request as received, but for the token (query parameter, Authorization header).
        lines = head.decode("latin-1").split("\r\n")
        lines[0] = f"{method} {forward_target} {version}"
        kept = [ln for ln in lines if not ln.lower().startswith("authorization:")]
        up_writer.write("\r\n".join(kept).encode("latin-1"))
        try:
            await asyncio.gather(_pump(reader, up_writer), _pump(up_reader, writer))
        finally:
            up_writer.close()
            self._writers.discard(up_writer)

    async def _read_head(self, reader: asyncio.StreamReader) -> bytes:
        if self._pending >= MAX_PENDING:
            raise _Refused("503 Service Unavailable", "too many handshakes at once")
        self._pending += 1
        try:
            return await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HANDSHAKE_TIMEOUT_S)
        except (TimeoutError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError) as exc:
            raise _Refused("400 Bad Request", f"no complete upgrade request ({type(exc).__name__})") from None
        finally:
            self._pending -= 1

    def close(self) -> None:
        if self._loop.is_closed():
            return

        async def shutdown() -> None:
            self._server.close()
            # Closing the sockets ends the pumps; cancelling the handler tasks instead makes
            # Python 3.11's asyncio.streams log a spurious traceback for each.
            for w in list(self._writers):
                w.close()
            if self._tasks:
                _done, pending = await asyncio.wait(list(self._tasks), timeout=5)
                for t in pending:
                    t.cancel()

        try:
            asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(timeout=10)
        finally:
            self._stop_loop()

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)
        if not self._thread.is_alive():
            self._loop.close()


def _parse_head(head: bytes) -> tuple[str, str, str, dict[str, list[str]]]:
    try:
        text = head.decode("latin-1")
    except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes every byte
        raise _Refused("400 Bad Request", "undecodable request") from None
    lines = text.split("\r\n")
    request = lines[0].split(" ")
    if len(request) != 3 or not request[2].startswith("HTTP/1."):
        raise _Refused("400 Bad Request", "not an HTTP/1.1 request line")
    headers: dict[str, list[str]] = {}
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(":")
        if not sep or not name or name != name.strip():
            raise _Refused("400 Bad Request", "malformed header line")
        headers.setdefault(name.lower(), []).append(value.strip())
    return request[0], request[1], request[2], headers


async def _reply(writer: asyncio.StreamWriter, status: str, reason: str) -> None:
    body = f"emos: {reason}\n".encode("utf-8", "replace")
    try:
        writer.write(f"HTTP/1.1 {status}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {len(body)}\r\n"
                     f"Connection: close\r\n\r\n".encode("latin-1") + body)
        await asyncio.wait_for(writer.drain(), 5)
    except (TimeoutError, OSError):
        pass
    finally:
        writer.close()


async def _pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
    try:
        while True:
            data = await src.read(_SPLICE_CHUNK)
            if not data:
                break
            dst.write(data)
            await dst.drain()  # backpressure: a slow viewer slows this copy, not our memory
    except (OSError, asyncio.IncompleteReadError):
        pass
    finally:
        try:
            if dst.can_write_eof():
                dst.write_eof()
        except OSError:
            pass


def _peer(peer: object) -> str:
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    return str(peer)
