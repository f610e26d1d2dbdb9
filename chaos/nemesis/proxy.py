"""A fault-injecting TCP proxy for model servers (and any TCP peer), with Toxiproxy-style toxics.

The recipe points its model client at the proxy (the runner exports
``EMOS_CHAOS_PROXY_<NAME>=host:port``); the nemesis adds and removes toxics while it runs:

* ``down``: refuse service (connections are accepted and closed at once);
* ``latency``: ``latency_ms`` (+ uniform ``jitter_ms``) before every chunk, both directions;
* ``bandwidth``: at most ``rate_kbps`` kilobytes per second;
* ``slicer``: chunks cut into ``average_size`` bytes with ``delay_ms`` between slices;
* ``timeout``: data stops flowing; the connection is closed after ``timeout_ms`` (0 = never);
* ``reset_peer``: the connection is reset (RST) ``timeout_ms`` after it opens;
* ``garbage``: the server's answer is replaced by random bytes of the same length;
* ``http_error``: every request is answered by the proxy itself with HTTP ``status`` (default
  503) and a JSON error body, as an overloaded or misconfigured model server would.
"""
from __future__ import annotations

import asyncio
import random
import socket
import struct
import threading
from typing import Any

from emos.chaos.history import Record
from emos.chaos.nemesis.base import Nemesis, NemesisError

TOXICS = ("down", "latency", "bandwidth", "slicer", "timeout", "reset_peer", "garbage", "http_error")


def parse_address(text: str, what: str) -> tuple[str, int]:
    host, _, port = str(text).rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 <= number <= 65535:
        raise NemesisError(f"{what}: expected host:port, got {text!r}")
    return host, number


class FaultProxy:
    """One listening address forwarding to one upstream, in its own thread and event loop."""

    def __init__(self, name: str, upstream: str, listen: str = "127.0.0.1:0") -> None:
        self.name = name
        self.upstream = parse_address(upstream, f"proxy {name!r} upstream")
        self.listen = parse_address(listen, f"proxy {name!r} listen")
        if self.listen[0] not in ("127.0.0.1", "localhost", "::1"):
            raise NemesisError(f"proxy {name!r}: listens on loopback addresses only, got {self.listen[0]!r}")
        self.toxics: dict[str, dict[str, Any]] = {}
        self.address: tuple[str, int] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.AbstractServer | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._rng = random.Random(0)
        self.connections = 0

    # -- control (any thread) ---------------------------------------------------------------------
    def start(self) -> tuple[str, int]:
        self._thread = threading.Thread(target=self._run, name=f"chaos-proxy-{self.name}", daemon=True)
        self._thread.start()
        if not self._ready.wait(5.0) or self.address is None:
            raise RuntimeError(f"proxy {self.name!r} could not listen on {self.listen}")
        return self.address

    def set_toxic(self, toxic: str, **params: Any) -> None:
        if toxic not in TOXICS:
            raise NemesisError(f"proxy {self.name!r}: unknown toxic {toxic!r}; toxics: {', '.join(TOXICS)}")
        self.toxics[toxic] = params
        if toxic in ("down", "reset_peer", "timeout", "garbage", "http_error") and self._loop is not None:
            # Faults that concern the connection must hit the ones already open, not only new ones.
            self._loop.call_soon_threadsafe(self._cut_open_connections)

    def remove_toxic(self, toxic: str) -> None:
        self.toxics.pop(toxic, None)

    def stop(self) -> None:
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    # -- the proxy (its own loop) -----------------------------------------------------------------
    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)  # this thread's own loop (gather at shutdown looks it up)
        self._loop = loop
        try:
            self._server = loop.run_until_complete(asyncio.start_server(self._handle, *self.listen))
            self.address = self._server.sockets[0].getsockname()[:2]
            self._ready.set()
            loop.run_forever()
        finally:
            self._ready.set()
            if self._server is not None:
                self._server.close()
            for w in list(self._writers):
                w.transport.abort()
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            for t in pending:  # connections still being pumped end here, not as "destroyed" tasks
                t.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.close()

    def _cut_open_connections(self) -> None:
        for w in list(self._writers):
            _reset(w)

    async def _handle(self, client_r: asyncio.StreamReader, client_w: asyncio.StreamWriter) -> None:
        self.connections += 1
        if "down" in self.toxics:
            _reset(client_w)
            return
        error = self.toxics.get("http_error")
        if error is not None:
            await self._answer_http_error(client_r, client_w, int(error.get("status", 503)))
            return
        try:
            server_r, server_w = await asyncio.open_connection(*self.upstream)
        except OSError:
            _reset(client_w)
            return
        self._writers.update((client_w, server_w))
        tasks = [asyncio.ensure_future(self._pump(client_r, server_w, upstream=True)),
                 asyncio.ensure_future(self._pump(server_r, client_w, upstream=False))]
        reset = self.toxics.get("reset_peer")
        if reset is not None:
            tasks.append(asyncio.ensure_future(self._reset_after(float(reset.get("timeout_ms", 0)) / 1000.0, client_w, server_w)))
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            for w in (client_w, server_w):
                self._writers.discard(w)
                w.close()

    async def _answer_http_error(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, status: int) -> None:
        """Read one request head and answer it with ``status``; the upstream is never contacted."""
        try:
            await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), timeout=5.0)
        except (TimeoutError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError):
            pass
        body = b'{"error": "injected by the EMOS chaos proxy"}'
        head = (f"HTTP/1.1 {status} Injected Error\r\nContent-Type: application/json\r\n"
                f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode()
        try:
            writer.write(head + body)
            await writer.drain()
        except ConnectionError:
            pass
        writer.close()

    async def _reset_after(self, seconds: float, *writers: asyncio.StreamWriter) -> None:
        await asyncio.sleep(seconds)
        for w in writers:
            _reset(w)

    async def _pump(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, upstream: bool) -> None:
        while True:
            chunk = await reader.read(65536)
            if not chunk:
                writer.close()
                return
            timeout = self.toxics.get("timeout")
            if timeout is not None:
                ms = float(timeout.get("timeout_ms", 0))
                await asyncio.sleep(ms / 1000.0 if ms > 0 else 3600.0)
                _reset(writer)
                return
            latency = self.toxics.get("latency")
            if latency is not None:
                delay = float(latency.get("latency_ms", 0)) + self._rng.uniform(0, float(latency.get("jitter_ms", 0)))
                await asyncio.sleep(delay / 1000.0)
            if not upstream and "garbage" in self.toxics:
                chunk = bytes(self._rng.getrandbits(8) for _ in range(len(chunk)))
            slicer = self.toxics.get("slicer")
            size = int(slicer.get("average_size", 64)) if slicer else len(chunk)
            for i in range(0, len(chunk), max(1, size)):
                piece = chunk[i : i + max(1, size)]
                bandwidth = self.toxics.get("bandwidth")
                if bandwidth is not None:
                    await asyncio.sleep(len(piece) / (1024.0 * max(0.001, float(bandwidth.get("rate_kbps", 100)))))
                writer.write(piece)
                await writer.drain()
                if slicer:
                    await asyncio.sleep(float(slicer.get("delay_ms", 10)) / 1000.0)


def _reset(writer: asyncio.StreamWriter) -> None:
    """Close with RST (SO_LINGER 0), as a crashed peer or a firewall would."""
    sock = writer.get_extra_info("socket")
    if sock is not None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        except OSError:
            pass
    writer.transport.abort()


class ProxyFault(Nemesis):
    """Add one toxic to a named proxy for the fault's duration."""

    kind = "proxy"
    summary = "model server faults through a TCP proxy: down, latency, bandwidth, slicer, timeout, reset_peer, garbage"
    expects = "healthy"

    def __init__(self, proxy: str, toxic: str, target: str | None = None, **params: Any) -> None:
        super().__init__(proxy=proxy, toxic=toxic, **({"target": target} if target else {}), **params)
        if toxic not in TOXICS:
            raise NemesisError(f"proxy fault: unknown toxic {toxic!r}; toxics: {', '.join(TOXICS)}")
        self.proxy_name, self.toxic, self.target, self.toxic_params = proxy, toxic, target, params
        self.proxies: dict[str, FaultProxy] = {}

    def start(self) -> Record | None:
        proxy = self.proxies.get(self.proxy_name)
        if proxy is None:
            raise NemesisError(f"proxy fault: the scenario declares no proxy {self.proxy_name!r}; declared: {', '.join(self.proxies) or 'none'}")
        proxy.set_toxic(self.toxic, **self.toxic_params)
        return self._fault(target=self.target or self.proxy_name, proxy=self.proxy_name, toxic=self.toxic)

    def stop(self) -> None:
        proxy = self.proxies.get(self.proxy_name)
        if proxy is not None:
            proxy.remove_toxic(self.toxic)
        super().stop()
