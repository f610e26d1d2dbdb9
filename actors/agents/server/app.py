"""Assembles the local model server: one aiohttp app (OpenAI, Ollama and RoboML HTTP/WebSocket
routes) plus an optional RESP listener, all on one asyncio loop in one process."""
from __future__ import annotations

import asyncio
import logging
import signal
from typing import Any

from aiohttp import web

from .backends import LocalModels
from .ollama_routes import add_ollama_routes
from .openai_routes import add_openai_routes
from .resp_server import start_resp_server
from .roboml_nodes import RoboMLNodes
from .roboml_routes import add_roboml_routes

__all__ = ["build_app", "serve"]

log = logging.getLogger("emos.agents.server")


def build_app(models: LocalModels) -> tuple[web.Application, RoboMLNodes]:
    app = web.Application(client_max_size=64 * 1024 * 1024)
    nodes = RoboMLNodes(models)
    # Fixed prefixes first: RoboML's catch-all /{node}/... routes must not shadow them.
    add_openai_routes(app, models)
    add_ollama_routes(app, models)
    add_roboml_routes(app, nodes)
    return app, nodes


class ListenError(OSError):
    """A listener could not bind; the message names which one and its port."""


async def _listen(what: str, host: str, port: int, starting: Any) -> Any:
    try:
        return await starting
    except OSError as exc:
        raise ListenError(f"cannot listen for {what} on {host}:{port}: {exc.strerror or exc}") from exc


async def serve(models: LocalModels, host: str = "127.0.0.1", port: int = 8000, resp_port: int | None = None,
                lerobot_port: int | None = None, ready: Any = None) -> None:
    """Serve until SIGTERM/SIGINT, then close listeners and in-flight connections cleanly."""
    app, nodes = build_app(models)
    runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=2.0)
    await runner.setup()
    site = web.TCPSite(runner, host, port, reuse_address=True)
    resp = policy = None
    listening = "HTTP"
    try:
        await _listen("HTTP", host, port, site.start())
        if resp_port is not None:
            resp = await _listen("RESP", host, resp_port, start_resp_server(nodes, host, resp_port))
        if lerobot_port is not None:
            from .lerobot_policy import HoldPositionPolicyServer  # grpc threads start only if asked

            listening = "LeRobot gRPC"
            policy = HoldPositionPolicyServer(host, lerobot_port).start()
    except BaseException as exc:
        # Release what did start, and name the listener that failed (not always --port).
        if resp is not None:
            await resp.close()
        await runner.cleanup()
        if isinstance(exc, OSError) and not isinstance(exc, ListenError) and listening != "HTTP":
            raise ListenError(f"cannot listen for {listening} on {host}:{lerobot_port}: {exc}") from exc
        raise
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError):  # not the main thread (tests run it in one)
            pass
    bound = [s.getsockname()[1] for s in site._server.sockets]  # port 0 -> the real port
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
