"""Who may use the page: whoever holds the access token, from the page's own origin only.

Every request, loopback included, must carry the access token (another local user can reach a
loopback port too, and the page can stop components): ``?token=`` once (the page then keeps it
in an HttpOnly, SameSite=Strict cookie), the cookie, or ``Authorization: Bearer``.

A web page elsewhere must not drive the robot through the user's browser:

* bound to a loopback address, the ``Host`` header must name this machine (DNS rebinding);
* a request with an ``Origin`` must come from the page's own origin (``Origin: null``, sent by
  sandboxed frames and local files, is refused like any foreign origin);
* every state-changing request (POST) carries the session's CSRF token in the ``X-EMOS-CSRF``
  header, and the websocket handshake in its ``csrf`` query parameter. The token is
  HMAC(access token, session cookie): only script of the page's own origin can read it (it is
  embedded in ``index.html`` and returned by ``GET /api/session``), and it stays valid while
  the UI process is restarted, since both inputs survive a restart;
* JSON POSTs must say ``Content-Type: application/json``: a cross-origin page can send
  ``text/plain`` without a CORS preflight, but not that.

Cookies ignore ports, so their names carry the UI's port: two recipes' pages on one machine do
not overwrite each other's cookies.
"""
from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from aiohttp import web

from emos.hosts import LOOPBACK_NAMES, host_of, is_loopback, same_origin

CSRF_HEADER = "X-EMOS-CSRF"
CSRF_QUERY = "csrf"
SESSION_ROUTES = ("/", "/api/session")  # GETs that hand out (and start, if needed) a session
UPLOAD_PREFIX = "/api/upload/"  # raw bodies (WAV, pictures) with their own content types
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
_SESSION_RE = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
# Set on SESSION_ROUTES for the handler (a typed key where aiohttp has them, >= 3.12).
CSRF_KEY: Any = web.RequestKey("emos_csrf", str) if hasattr(web, "RequestKey") else "emos_csrf"


def new_token() -> str:
    return secrets.token_urlsafe(18)


def token_cookie(port: int) -> str:
    return f"emos_ui_token_{port}"


def session_cookie(port: int) -> str:
    return f"emos_ui_session_{port}"


def csrf_for(token: str, session: str) -> str:
    """The CSRF token of ``session``: nobody without the access token can compute it."""
    return hmac.new(token.encode(), b"emos-ui-csrf:" + session.encode(), hashlib.sha256).hexdigest()


def _refuse(status: int, text: str, **headers: str) -> web.Response:
    return web.Response(status=status, text=f"EMOS UI: {text}\n", headers=headers)


def _given_token(request: web.Request, cookie: str) -> str:
    given = request.query.get("token") or request.cookies.get(cookie) or ""
    auth = request.headers.get("Authorization", "")
    if not given and auth.startswith("Bearer "):
        given = auth[7:].strip()
    return given


def make_middleware(bind_host: str, token: str, port: int, token_file: Path | None = None) -> Callable[..., Awaitable[web.StreamResponse]]:
    """The checks above, in order: Host, Origin, access token (401), then for POSTs the content
    type (415) and the CSRF token (403), for the websocket the CSRF token (403)."""
    if not token:
        raise ValueError(f"the UI on {bind_host}:{port} needs an access token (UIConfig.token); "
                         "enable_ui and UIComponent make one when none is given")
    local_only = is_loopback(bind_host)
    tok_cookie, sess_cookie = token_cookie(port), session_cookie(port)
    where = f" or read it from {token_file}" if token_file is not None else ""

    @web.middleware
    async def check(request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]) -> web.StreamResponse:
        host = request.headers.get("Host", "")
        if local_only and host_of(host) not in LOOPBACK_NAMES:
            return _refuse(403, "this page is served to this machine only (Host not allowed)")
        origin = request.headers.get("Origin")
        if origin is not None and not same_origin(origin, host):
            return _refuse(403, f"cross-origin request refused (Origin {origin!r}; only pages of http://{host} may call it)")
        if not hmac.compare_digest(_given_token(request, tok_cookie).encode(), token.encode()):
            return _refuse(401, f"access token required: open the address printed at start-up (.../?token=...){where}, "
                                "or send 'Authorization: Bearer <token>'", **{"WWW-Authenticate": 'Bearer realm="EMOS UI"'})
        session = request.cookies.get(sess_cookie, "")
        session = session if _SESSION_RE.match(session) else ""
        if request.method not in SAFE_METHODS:
            if not request.path.startswith(UPLOAD_PREFIX):
                ctype = request.headers.get("Content-Type")
                if ctype is None or request.content_type != "application/json":
                    return _refuse(415, f"{request.method} {request.path} needs 'Content-Type: application/json' "
                                        f"(got {ctype or 'no Content-Type'})")
            refused = _check_csrf(request.headers.get(CSRF_HEADER), session, f"the {CSRF_HEADER} header")
            if refused is not None:
                return refused
        elif request.path == "/ws":
            refused = _check_csrf(request.query.get(CSRF_QUERY), session, f"the '{CSRF_QUERY}' query parameter of the websocket address")
            if refused is not None:
                return refused
        if request.query.get("token") and request.method == "GET" and request.path == "/":
            # Keep the token in a cookie and take it out of the address bar (and so out of the
            # history, bookmarks and screenshots).
            redirect = web.Response(status=303, headers={"Location": "/"})
            redirect.set_cookie(tok_cookie, token, httponly=True, samesite="Strict")
            return redirect
        new_session = ""
        if request.method in ("GET", "HEAD") and request.path in SESSION_ROUTES:
            if not session:
                session = new_session = secrets.token_urlsafe(24)
            request[CSRF_KEY] = csrf_for(token, session)
        response = await handler(request)
        if new_session and not response.prepared:
            response.set_cookie(sess_cookie, new_session, httponly=True, samesite="Strict")
        if request.query.get("token") and request.path != "/ws" and not response.prepared:
            response.set_cookie(tok_cookie, token, httponly=True, samesite="Strict")
        return response

    def _check_csrf(given: str | None, session: str, carrier: str) -> web.Response | None:
        if not session:
            return _refuse(403, "no session cookie: load the page (GET /) or GET /api/session first, then send its CSRF token in " + carrier)
        if not given:
            return _refuse(403, f"CSRF token missing: send the page's CSRF token in {carrier}")
        if not hmac.compare_digest(given.encode(), csrf_for(token, session).encode()):
            return _refuse(403, f"wrong CSRF token in {carrier} (reload the page)")
        return None

    return check


SECURITY_HEADERS: dict[str, Any] = {
    # Nothing the page loads or connects to may leave this server.
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; media-src 'self' blob:; "
                               "connect-src 'self'; style-src 'self'; script-src 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
