"""Who may use the page: local-only by default, a token for anything else.

* Bound to a loopback address, requests must name this machine in their ``Host`` header (so a
  web page elsewhere cannot reach the robot through DNS rebinding) and websockets must come from
  a page of ours (``Origin``).
* Bound to any other address, every request must carry the token: ``?token=`` once (the page
  then keeps it in a same-site cookie), the cookie, or ``Authorization: Bearer``.
"""
from __future__ import annotations

import hmac
import secrets
from typing import Any, Awaitable, Callable
from urllib.parse import urlsplit

from aiohttp import web

from emos.actors.ui.config import LOOPBACK_NAMES, is_loopback

COOKIE = "emos_ui_token"


def new_token() -> str:
    return secrets.token_urlsafe(18)


def _host_name(host_header: str) -> str:
    host = host_header.strip()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def make_middleware(bind_host: str, token: str) -> Callable[..., Awaitable[web.StreamResponse]]:
    local_only = is_loopback(bind_host)
    if not local_only and not token:
        raise ValueError(f"the UI listens on {bind_host}, which is not a loopback address: it needs an access token")

    @web.middleware
    async def check(request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]) -> web.StreamResponse:
        if local_only:
            if _host_name(request.headers.get("Host", "")) not in LOOPBACK_NAMES:
                return web.Response(status=403, text="EMOS UI: this page is served to this machine only (Host not allowed)\n")
        origin = request.headers.get("Origin")
        if origin and origin != "null" and urlsplit(origin).netloc != request.headers.get("Host", ""):
            return web.Response(status=403, text="EMOS UI: cross-origin request refused\n")
        if token:
            given = request.query.get("token") or request.cookies.get(COOKIE) or ""
            auth = request.headers.get("Authorization", "")
            if not given and auth.startswith("Bearer "):
                given = auth[7:]
            if not hmac.compare_digest(given.encode(), token.encode()):
                return web.Response(status=401, text="EMOS UI: access token required (open the address printed at start-up)\n")
            if request.query.get("token"):
                # Keep the token in a cookie and take it out of the address bar (and so out of
                # the history, bookmarks and screenshots).
                response: web.StreamResponse
                if request.method == "GET" and request.path == "/":
                    response = web.Response(status=303, headers={"Location": "/"})
                else:
                    response = await handler(request)
                response.set_cookie(COOKIE, token, httponly=True, samesite="Strict")
                return response
            return await handler(request)
        return await handler(request)

    return check


SECURITY_HEADERS: dict[str, Any] = {
    # Nothing the page loads or connects to may leave this server.
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; media-src 'self' blob:; "
                               "connect-src 'self'; style-src 'self'; script-src 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
