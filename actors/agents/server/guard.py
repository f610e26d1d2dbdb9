"""Who may call the model server over HTTP, with what, and what a bad request gets back.

The server has no token: its protection is that only this machine reaches it. That holds only
if a web page cannot make the browser talk to it, so (the same rules as the web UI,
``actors/ui/auth.py``):

* bound to a loopback address, a request must name this machine in ``Host``: a page of
  ``evil.example`` rebound by DNS to 127.0.0.1 sends ``Host: evil.example``;
* a request from a web page (it has an ``Origin`` header) must come from this server's own
  origin; ``null`` (sandboxed frames, ``file://`` pages) is refused too;
* JSON routes take only ``application/json``: a cross-origin "simple" request, which a browser
  sends without asking first, can only be text/plain, form-encoded or multipart; routes that
  take their arguments in the query string (RoboML's ``add_node``/``remove_node``) refuse a body.

Request bodies are bounded per request (``client_max_size``) and across requests (the server's
:class:`~.limits.ByteBudget`), and an error that escapes a handler becomes a JSON error in the
API's own shape, never aiohttp's bare 500 page.
"""
from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable

from aiohttp import web

from emos.hosts import LOOPBACK_NAMES, host_of, is_loopback, same_origin
from emos.ratelimit import RateLimitedLog

from .limits import MAX_HTTP_BODY, ByteBudget, MiB

__all__ = ["make_guard", "takes_json", "takes_no_body", "error_response"]

log = logging.getLogger("emos.agents.server")
_refusals = RateLimitedLog(log, interval=10.0)
Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]
#: the content types a browser sends cross-origin without a CORS preflight
SIMPLE_TYPES = ("text/plain", "application/x-www-form-urlencoded", "multipart/form-data")


def takes_json(handler: Handler) -> Handler:
    """Mark a route whose body is JSON: it then requires ``Content-Type: application/json``."""
    handler.takes_json = True  # type: ignore[attr-defined]
    return handler


def takes_no_body(handler: Handler) -> Handler:
    """Mark a route whose arguments are all in the query string: it then refuses a body."""
    handler.takes_no_body = True  # type: ignore[attr-defined]
    return handler


def error_response(request: web.Request, status: int, message: str) -> web.Response:
    """An error in the shape of the API the path belongs to: OpenAI, Ollama or RoboML."""
    if request.path.startswith("/v1/"):
        kind = "server_error" if status >= 500 else "invalid_request_error"
        return web.json_response({"error": {"message": message, "type": kind, "param": None, "code": None}}, status=status)
    if request.path.startswith("/api/"):
        return web.json_response({"error": message}, status=status)
    return web.json_response({"detail": message}, status=status)


def _peer(request: web.Request) -> str:
    return str(request.remote or "?")


def make_guard(bind_host: str, budget: ByteBudget) -> Callable[..., Awaitable[web.StreamResponse]]:
    local_only = is_loopback(bind_host)

    def refuse(request: web.Request, status: int, message: str) -> web.Response:
        _refusals.warning(f"{status}:{_peer(request)}:{message[:24]}", "model server: refused %s %s from %s: %s",
                          request.method, request.path, _peer(request), message)
        return error_response(request, status, message)

    @web.middleware
    async def guard(request: web.Request, handler: Handler) -> web.StreamResponse:
        host = request.headers.get("Host", "")
        if local_only and host_of(host) not in LOOPBACK_NAMES:
            return refuse(request, 403, f"this model server is served to this machine only (Host {host[:80]!r} "
                                        f"is not one of {', '.join(LOOPBACK_NAMES)})")
        origin = request.headers.get("Origin")
        if origin is not None and not same_origin(origin, host):
            return refuse(request, 403, f"cross-origin request refused (Origin {origin[:80]!r} "
                                        f"is not this server, http://{host[:80]})")
        route = request.match_info.handler
        if getattr(route, "takes_json", False) and request.content_type != "application/json":
            return refuse(request, 415, f"{request.path} takes a JSON body: send 'Content-Type: application/json' "
                                        f"(got {request.headers.get('Content-Type', 'none')!r})")
        if getattr(route, "takes_no_body", False) and (
                request.body_exists or ("Content-Type" in request.headers and request.content_type in SIMPLE_TYPES)):
            return refuse(request, 415, f"{request.path} takes its arguments in the query string; send no body")
        size = 0
        if request.body_exists:
            size = request.content_length if request.content_length is not None else MAX_HTTP_BODY
            if size > MAX_HTTP_BODY:
                return refuse(request, 413, f"request body of {size} bytes exceeds the {MAX_HTTP_BODY // MiB} MiB limit")
            if not budget.take(size):
                return refuse(request, 503, f"server busy: {budget.describe()}; try again")
        try:
            return await handler(request)
        except (web.HTTPException, ConnectionError):  # a client that left mid-stream is aiohttp's to handle
            raise
        except RecursionError:
            return error_response(request, 400, "request is nested too deeply")
        except Exception as exc:  # a bug, not the client's fault: say so in one line, keep details in the log
            log.exception("model server: %s %s failed", request.method, request.path)
            return error_response(request, 500, f"internal error in the model server ({type(exc).__name__}); "
                                                "see its log")
        finally:
            if size:
                budget.give(size)

    return guard
