"""Assembles the local model server: one aiohttp app (OpenAI, Ollama and RoboML HTTP/WebSocket
routes) plus an optional RESP listener, all on one asyncio loop in one process."""
from __future__ import annotations

import asyncio
import errno
import logging
import signal
import socket
from typing import Any

from aiohttp import web

from emos.errors import EmosError

from .backends import LocalModels
from .guard import make_guard
from .limits import MAX_HTTP_BODY, ByteBudget
from .ollama_routes import add_ollama_routes
from .openai_routes import add_openai_routes
from .resp_server import start_resp_server
from .roboml_nodes import RoboMLNodes
from .roboml_routes import add_roboml_routes

__all__ = ["build_app", "serve", "ListenError"]

log = logging.getLogger("emos.agents.server")


def build_app(models: LocalModels, host: str = "127.0.0.1",
              budget: ByteBudget | None = None) -> tuple[web.Application, RoboMLNodes]:
    """The HTTP app for a server bound to ``host`` (loopback binds check ``Host``, see guard.py)."""
    app = web.Application(client_max_size=MAX_HTTP_BODY, middlewares=[make_guard(host, budget or ByteBudget())])
    nodes = RoboMLNodes(models)
    # Fixed prefixes first: RoboML's catch-all /{node}/... routes must not shadow them.
    add_openai_routes(app, models)
    add_ollama_routes(app, models)
    add_roboml_routes(app, nodes)
    return app, nodes


class ListenError(EmosError, OSError):
    """A listener could not bind; the message names which one, its address and why."""


def listen_error(what: str, host: str, port: int, exc: BaseException) -> ListenError:
    if getattr(exc, "errno", None) == errno.EADDRINUSE:
        reason = "address in use"
    else:
        reason = getattr(exc, "strerror", None) or str(exc)
    return ListenError(f"cannot listen on {host}:{port} for the {what} server: {reason}")


async def _listen(what: str, host: str, port: int, starting: Any) -> Any:
    try:
        return await starting
    except OSError as exc:
        raise listen_error(what, host, port, exc) from exc


def check_free(what: str, host: str, port: int) -> None:
    """Bind ``host:port`` once and let go, so a taken port is reported by name before a library
    that says less (gRPC: "Failed to bind") tries it. Port 0 is always free."""
    if port == 0:
        return
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is free
            probe.bind(address)
    except OSError as exc:
        raise listen_error(what, host, port, exc) from exc


async def serve(models: LocalModels, host: str = "127.0.0.1", port: int = 8000, resp_port: int | None = None,
                lerobot_port: int | None = None, ready: Any = None) -> int | None:
    """Serve until SIGTERM/SIGINT, then close listeners and in-flight connections cleanly.

    Returns the number of the signal that ended it (None if none did: not the main thread)."""
    budget = ByteBudget()  # request bytes in flight, HTTP and RESP together
    app, nodes = build_app(models, host, budget)
    runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=2.0)
    await runner.setup()
    site = web.TCPSite(runner, host, port, reuse_address=True)
    resp = policy = None
    try:
        await _listen("HTTP", host, port, site.start())
        if resp_port is not None:
            resp = await _listen("RESP", host, resp_port, start_resp_server(nodes, host, resp_port, budget))
        if lerobot_port is not None:
            check_free("LeRobot", host, lerobot_port)
            from .lerobot_policy import HoldPositionPolicyServer  # grpc threads start only if asked

            try:
                policy = HoldPositionPolicyServer(host, lerobot_port).start()
            except OSError as exc:
                raise listen_error("LeRobot", host, lerobot_port, exc) from exc
    except BaseException:
        # Release what did start.
        if resp is not None:
            await resp.close()
        await runner.cleanup()
        raise
    stop = asyncio.Event()
    received: list[int] = []
    loop = asyncio.get_running_loop()

    def on_signal(signum: int) -> None:
        received.append(signum)
        stop.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, on_signal, sig)
        except (NotImplementedError, RuntimeError):  # not the main thread (tests run it in one)
            pass
    bound = [address[1] for address in runner.addresses]  # port 0 -> the real port (the one site: ours)
    resp_bound = resp.port if resp else None
    log.info("serving on http://%s:%s (RESP %s)", host, bound[0], resp_bound)
    # One parseable line so supervisors and tests know when (and where) the server listens.
    lerobot_bound = policy.port if policy else None
    print(f"emos-model-server ready http={host}:{bound[0]} resp={resp_bound or '-'} lerobot={lerobot_bound or '-'}",
          flush=True)
    if ready is not None:
        ready(bound[0], resp_bound)
    try:
        await stop.wait()
    finally:
        if policy is not None:
            await asyncio.get_running_loop().run_in_executor(None, policy.stop)
        if resp is not None:
            await resp.close()
        await runner.cleanup()
    return received[0] if received else None
