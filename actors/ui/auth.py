"""Who may use the page and the API, with which role, from where.

Credentials (every request, loopback included: another local user can reach a loopback port
too, and the page can stop components):

* the run's access token (printed once as the sign-in link, kept in ``<run dir>/ui.token``):
  role ``operator``;
* a device token from pairing (:mod:`emos.actors.ui.pairing`, :mod:`emos.actors.ui.devices`):
  hashed at rest, expiring, revocable, with the role ``viewer`` or ``operator``.

Either comes as ``?token=`` once (the page then keeps it in an HttpOnly, SameSite=Strict
cookie, ``Secure`` over HTTPS), the cookie, or ``Authorization: Bearer``. Roles: a ``viewer``
may read (GET, the websocket's streams); everything that changes something (every POST, the
websocket's publish/goal/cancel) needs ``operator``. Wrong tokens and wrong pairing codes count
against the client (:class:`~emos.actors.ui.pairing.AttemptLimiter`, 429 when over), and every
refusal is logged, rate-limited per reason and client.

A web page elsewhere must not drive the robot through the user's browser:

* the ``Host`` header must name this machine (its loopback names; off loopback also its
  addresses, host name and ``UIConfig.allowed_hosts``): DNS rebinding;
* a request with an ``Origin`` must come from the page's own origin, scheme included
  (``Origin: null``, sent by sandboxed frames and local files, is refused like any foreign one);
* every state-changing request (POST) carries the session's CSRF token in the ``X-EMOS-CSRF``
  header, and the page's websocket handshake in its ``csrf`` query parameter. The token is
  HMAC(credential, session cookie): only script of the page's own origin can read it (it is
  embedded in ``index.html`` and returned by ``GET /api/session``). Under ``/api/v1/`` a request
  signed in with an ``Authorization`` header needs no CSRF token (a browser never adds that
  header by itself: CSRF rides on cookies only);
* JSON POSTs must say ``Content-Type: application/json``: a cross-origin page can send
  ``text/plain`` without a CORS preflight, but not that.

Cookies ignore ports, so their names carry the UI's port: two recipes' pages on one machine do
not overwrite each other's cookies.
"""
from __future__ import annotations

import hashlib
import hmac
import logging
import re
import secrets
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from aiohttp import web

from emos.actors.ui import pairing as pairing_mod
from emos.actors.ui.devices import ROLES, DeviceStore
from emos.hosts import LOOPBACK_NAMES, host_of, is_loopback
from emos.ratelimit import RateLimitedLog

log = logging.getLogger("emos.ui")
_refusals = RateLimitedLog(log, interval=10.0)  # one line per (reason, client) per 10 s, then counts

CSRF_HEADER = "X-EMOS-CSRF"
CSRF_QUERY = "csrf"
SESSION_ROUTES = ("/", "/api/session", "/api/v1/session")  # GETs that hand out (and start, if needed) a session
UPLOAD_PREFIX = "/api/upload/"  # raw bodies (WAV, pictures) with their own content types
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
_SESSION_RE = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
# Set on SESSION_ROUTES for the handler (a typed key where aiohttp has them, >= 3.12).
CSRF_KEY: Any = web.RequestKey("emos_csrf", str) if hasattr(web, "RequestKey") else "emos_csrf"
PRINCIPAL_KEY: Any = web.RequestKey("emos_principal", object) if hasattr(web, "RequestKey") else "emos_principal"
API_PREFIX = "/api/v1/"
PAIR_PATH = "/api/pair"
# Reachable without a credential: the pairing page, its assets (the same for everyone, no
# secrets), and the pairing call itself (rate-limited).
PUBLIC_GET = ("/pair", "/static/")
ROLE_RANK = {"viewer": 1, "operator": 2}


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


def _given_token(request: web.Request, cookie: str) -> tuple[str, str]:
    """(credential, where it came from: query, header, cookie or "")."""
    if request.query.get("token"):
        return request.query["token"], "query"
    auth = request.headers.get("Authorization", "")
    if auth.startswith("Bearer ") and auth[7:].strip():
        return auth[7:].strip(), "header"
    if request.cookies.get(cookie):
        return request.cookies[cookie], "cookie"
    return "", ""


class Principal:
    """Who a request is: the run's token or a paired device, with a role."""

    __slots__ = ("kind", "role", "device_id", "name", "credential", "via", "expires")

    def __init__(self, kind: str, role: str, credential: str, via: str, device_id: str = "", name: str = "", expires: float | None = None):
        self.kind, self.role, self.credential, self.via = kind, role, credential, via
        self.device_id, self.name, self.expires = device_id, name, expires

    def may(self, role: str) -> bool:
        return ROLE_RANK[self.role] >= ROLE_RANK[role]

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "role": self.role, "device": self.device_id or None, "name": self.name or None, "expires": self.expires}

    def __str__(self) -> str:
        return f"device {self.name!r} ({self.device_id}, {self.role})" if self.kind == "device" else f"the run's token ({self.role})"


def client_of(request: web.Request) -> str:
    return request.remote or "?"


def refused(what: str, request: web.Request, detail: str) -> None:
    """Log a refusal: once per (what, client) per 10 s, then how many were left out."""
    _refusals.warning((what, client_of(request)), "[ui] refused %s from %s: %s (%s %s)", what, client_of(request), detail,
                      request.method, request.path[:120])


class Gate:
    """The checks every request passes (see the module docstring), and pairing."""

    def __init__(self, bind_host: str, token: str, port: int, token_file: Path | None = None, *,
                 devices: DeviceStore | None = None, tls: bool = False, allowed_hosts: Any = (), failures_per_minute: int = 30,
                 pairing_code: str = "", pairing_role: str = "operator", token_ttl_s: float = 30 * 86400.0,
                 pairing_file: Path | None = None, base_url: str = "", serve_browser: bool = True,
                 pairing_ttl_s: float = 300.0, pairing_expires: float = 0.0, clock: Callable[[], float] = time.time) -> None:
        """``pairing_ttl_s``: how long a pairing code is valid; ``pairing_expires``: when the
        given ``pairing_code`` expires (UNIX time, as printed; 0: ``pairing_ttl_s`` from now);
        ``clock``: the wall clock (the printed expiry is one), injectable for tests."""
        if not token:
            raise ValueError(f"the UI on {bind_host}:{port} needs an access token (UIConfig.token); "
                             "enable_ui and UIComponent make one when none is given")
        self.token, self.port, self.token_file, self.devices, self.tls = token, port, token_file, devices, tls
        self.scheme = "https" if tls else "http"
        names = set(LOOPBACK_NAMES)
        if not is_loopback(bind_host):
            from emos.actors.ui.tls import machine_names

            names.update(machine_names(bind_host))
        names.update(str(h).strip("[]") for h in allowed_hosts or ())
        self.host_names = {n.lower() for n in names}
        self.tok_cookie, self.sess_cookie = token_cookie(port), session_cookie(port)
        self.limiter = pairing_mod.AttemptLimiter(failures_per_minute)
        self.pairing_code, self.pairing_role, self.token_ttl_s = pairing_code, pairing_role, token_ttl_s
        self.pairing_file, self.base_url = pairing_file, base_url
        if not pairing_ttl_s > 0:
            raise ValueError(f"the UI on {bind_host}:{port}: a pairing code's lifetime must be > 0 s, got {pairing_ttl_s!r}")
        self.clock, self.pairing_ttl_s = clock, float(pairing_ttl_s)
        self.pairing_expires = pairing_expires or clock() + self.pairing_ttl_s
        self.expired_code, self.expired_at = "", 0.0  # the last code that expired unused: refused with its own message
        self.paired = 0
        self.serve_browser = serve_browser
        if self.pairing_code and self._code_was_used(self.pairing_code):
            # A restarted UI process gets the printed code from its config: if a device paired
            # with it before the restart, it must not work again.
            self.new_pairing_code()

    # ------------------------------------------------------------------ credentials
    def authenticate(self, credential: str, via: str) -> tuple[Principal | None, str]:
        if hmac.compare_digest(credential.encode(), self.token.encode()):
            return Principal("token", "operator", credential, via), ""
        if self.devices is not None and credential.startswith("emosd_"):
            record, why = self.devices.check(credential)
            if record is not None:
                return Principal("device", record["role"], credential, via, record["id"], record["name"], record["expires"]), ""
            return None, why
        return None, "wrong access token"

    def still_valid(self, principal: Principal) -> bool:
        """Whether an open websocket of ``principal`` may stay open (revocation, expiry)."""
        if principal.kind != "device":
            return True
        return self.devices is not None and self.devices.still_valid(principal.device_id)

    def _set_cookie(self, response: web.StreamResponse, name: str, value: str) -> None:
        response.set_cookie(name, value, httponly=True, samesite="Strict", secure=self.tls)

    # ------------------------------------------------------------------ the middleware
    @web.middleware
    async def middleware(self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]) -> web.StreamResponse:
        host = request.headers.get("Host", "")
        if host_of(host).lower() not in self.host_names:
            refused("a request for a foreign Host", request, f"Host {host[:80]!r} is not a name of this machine")
            # The names it does answer to stay in the log: a forged Host must not learn them.
            return _refuse(403, f"Host {host[:80]!r} not allowed: not a name of this machine (add one with UIConfig.allowed_hosts)")
        origin = request.headers.get("Origin")
        if origin is not None and not self._same_origin(origin, host):
            refused("a cross-origin request", request, f"Origin {origin[:80]!r}")
            return _refuse(403, f"cross-origin request refused (Origin {origin!r}; only pages of {self.scheme}://{host} may call it)")
        path = request.path
        if request.method == "POST" and path == PAIR_PATH:
            return await self.pair(request)
        if request.method in ("GET", "HEAD") and (path == "/pair" or path.startswith("/static/")):
            return await handler(request)
        credential, via = _given_token(request, self.tok_cookie)
        if not credential:
            where = f" or read it from {self.token_file}" if self.token_file is not None else ""
            return _refuse(401, f"access token required: open the address printed at start-up (.../?token=...){where}, "
                                "pair this device at /pair with the code the run printed, "
                                "or send 'Authorization: Bearer <token>'", **{"WWW-Authenticate": 'Bearer realm="EMOS UI"'})
        wait = self.limiter.blocked(client_of(request))
        if wait > 0:
            refused("a sign-in (too many failures)", request, f"blocked for {wait:.0f} s more")
            return _refuse(429, f"too many failed sign-ins from {client_of(request)}: try again in {wait:.0f} s",
                           **{"Retry-After": str(max(1, round(wait)))})
        principal, why = self.authenticate(credential, via)
        if principal is None:
            self.limiter.failed(client_of(request))
            refused("a token", request, why)
            return _refuse(401, f"access token refused: {why}", **{"WWW-Authenticate": 'Bearer realm="EMOS UI", error="invalid_token"'})
        request[PRINCIPAL_KEY] = principal
        if request.method not in SAFE_METHODS and not principal.may("operator"):
            refused("a viewer's change", request, f"{principal} may only watch")
            return _refuse(403, f"{principal} may only watch: {request.method} {path} needs the operator role")
        session = request.cookies.get(self.sess_cookie, "")
        session = session if _SESSION_RE.match(session) else ""
        header_signed = via == "header" and path.startswith(API_PREFIX)
        if request.method not in SAFE_METHODS:
            # Raw uploads keep their own content types; an API client signed in by header is no
            # cross-site form (the API's handlers check the content types they take).
            if not path.startswith(UPLOAD_PREFIX) and not header_signed:
                ctype = request.headers.get("Content-Type")
                if ctype is None or request.content_type != "application/json":
                    return _refuse(415, f"{request.method} {path} needs 'Content-Type: application/json' "
                                        f"(got {ctype or 'no Content-Type'})")
            if not header_signed:
                bad = self._check_csrf(request.headers.get(CSRF_HEADER), session, principal, f"the {CSRF_HEADER} header")
                if bad is not None:
                    return bad
        elif path in ("/ws", API_PREFIX + "ws") and not header_signed:
            bad = self._check_csrf(request.query.get(CSRF_QUERY), session, principal, f"the '{CSRF_QUERY}' query parameter of the websocket address")
            if bad is not None:
                return bad
        if via == "query" and request.method == "GET" and path == "/" and self.serve_browser:
            # Keep the token in a cookie and take it out of the address bar (and so out of the
            # history, bookmarks and screenshots).
            redirect = web.Response(status=303, headers={"Location": "/"})
            self._set_cookie(redirect, self.tok_cookie, credential)
            return redirect
        new_session = ""
        if request.method in ("GET", "HEAD") and path in SESSION_ROUTES:
            if not session:
                session = new_session = secrets.token_urlsafe(24)
            request[CSRF_KEY] = csrf_for(credential, session)
        response = await handler(request)
        if new_session and not response.prepared:
            self._set_cookie(response, self.sess_cookie, new_session)
        if via == "query" and path != "/ws" and not response.prepared:
            self._set_cookie(response, self.tok_cookie, credential)
        return response

    def _same_origin(self, origin: str, host: str) -> bool:
        try:
            parts = urlsplit(origin)
        except ValueError:
            return False
        return parts.scheme == self.scheme and bool(host) and parts.netloc.lower() == host.strip().lower()

    def _check_csrf(self, given: str | None, session: str, principal: Principal, carrier: str) -> web.Response | None:
        if not session:
            return _refuse(403, "no session cookie: load the page (GET /) or GET /api/session first, then send its CSRF token in " + carrier)
        if not given:
            return _refuse(403, f"CSRF token missing: send the page's CSRF token in {carrier}")
        if not hmac.compare_digest(given.encode(), csrf_for(principal.credential, session).encode()):
            return _refuse(403, f"wrong CSRF token in {carrier} (reload the page)")
        return None

    # ------------------------------------------------------------------ pairing
    async def pair(self, request: web.Request) -> web.Response:
        """``POST /api/pair {"code", "name"[, "role"]}``: a device token for the right code."""
        client = client_of(request)
        if request.content_type != "application/json":
            return _json(415, {"ok": False, "error": "POST /api/pair needs 'Content-Type: application/json'"})
        wait = self.limiter.blocked(client)
        if wait > 0:
            refused("a pairing attempt (too many failures)", request, f"blocked for {wait:.0f} s more")
            return _json(429, {"ok": False, "error": f"too many failed attempts from {client}: try again in {wait:.0f} s"},
                         {"Retry-After": str(max(1, round(wait)))})
        try:
            body = await request.json()
        except ValueError:
            body = None
        if not isinstance(body, dict):
            return _json(400, {"ok": False, "error": "expected a JSON object {\"code\": ..., \"name\": ...}", "field": "body"})
        if self.devices is None or not self.pairing_code:
            return _json(404, {"ok": False, "error": "pairing is off for this UI (UIConfig.pairing)"})
        if not isinstance(body.get("code"), str):
            return _json(422, {"ok": False, "error": "code: expected the pairing code as text", "field": "code"})
        code = self.current_code()  # an expired code is replaced here, before it is compared
        if self.expired_code and pairing_mod.same_code(body["code"], self.expired_code):
            # Not counted as a guess: only someone who was shown the code can send it.
            refused("an expired pairing code", request, f"expired at {pairing_mod.until_text(self.expired_at)}")
            return _json(401, {"ok": False, "error": f"this pairing code expired at {pairing_mod.until_text(self.expired_at)} "
                                                     f"(codes are valid {pairing_mod.lifetime_text(self.pairing_ttl_s)}): "
                                                     "run `emos ui pair` on the robot for the current one", "expired": True})
        if not pairing_mod.same_code(body["code"], code):
            self.limiter.failed(client)
            refused("a pairing code", request, "wrong code")
            return _json(401, {"ok": False, "error": "wrong or used pairing code"})
        role = body.get("role", self.pairing_role)
        if role not in ROLES or ROLE_RANK[role] > ROLE_RANK[self.pairing_role]:
            return _json(422, {"ok": False, "error": f"role: may be {', '.join(r for r in ROLES if ROLE_RANK[r] <= ROLE_RANK[self.pairing_role])}, "
                                                      f"got {role!r}", "field": "role"})
        name = body.get("name") or f"device at {client}"
        try:
            token, record = self.devices.issue(str(name)[:64] if isinstance(name, str) else "", role, self.token_ttl_s,
                                               pairing=pairing_mod.code_digest(code))
        except ValueError as exc:
            return _json(422, {"ok": False, "error": f"name: {exc}", "field": "name"})
        self.paired += 1
        log.info("[ui] paired device %r (%s) from %s as %s, valid until %s", record["name"], record["id"], client, role,
                 time.strftime("%Y-%m-%d %H:%M", time.localtime(record["expires"])))
        self.new_pairing_code()
        response = _json(200, {"ok": True, "token": token, "device": record})
        self._set_cookie(response, self.tok_cookie, token)
        return response

    def current_code(self) -> str:
        """The pairing code in force: an expired one is replaced first (and remembered, so that a
        device sending it is told it expired rather than that it is wrong)."""
        if self.pairing_code and self.clock() >= self.pairing_expires:
            self.expired_code, self.expired_at = self.pairing_code, self.pairing_expires
            self.new_pairing_code(announce=False)
            log.info("[ui] port %d: the pairing code expired at %s; the next one is valid until %s (`emos ui pair` shows it)",
                     self.port, pairing_mod.until_text(self.expired_at), pairing_mod.until_text(self.pairing_expires))
        return self.pairing_code

    def write_pairing_file(self) -> None:
        if self.pairing_file is None or not self.pairing_code:
            return
        url = pairing_mod.pairing_url(self.base_url, self.pairing_code) if self.base_url else ""
        try:
            pairing_mod.write_pairing_file(self.pairing_file, self.pairing_code, url, self.pairing_role, self.pairing_expires)
        except OSError as exc:
            log.error("[ui] port %d: cannot write the pairing code to %s: %s", self.port, self.pairing_file, exc)

    def new_pairing_code(self, announce: bool = True) -> str:
        """A fresh single-use code valid ``pairing_ttl_s`` (the old one stops working), written to
        the pairing file and (``announce``) logged."""
        self.pairing_code = pairing_mod.new_code()
        self.pairing_expires = self.clock() + self.pairing_ttl_s
        self.write_pairing_file()
        if announce:
            log.info("[ui] next pairing code: %s, valid until %s (also shown by `emos ui pair`)", self.pairing_code,
                     pairing_mod.until_text(self.pairing_expires))
        return self.pairing_code

    def _code_was_used(self, code: str) -> bool:
        if self.devices is None:
            return False
        digest = pairing_mod.code_digest(code)
        try:
            return any(r.get("pairing") == digest for r in self.devices.records())
        except Exception as exc:  # an unusable store: pairing will refuse anyway; be safe and change the code
            log.warning("[ui] port %d: cannot read the device store (%s): making a new pairing code", self.port, exc)
            return True


def _json(status: int, body: dict[str, Any], headers: dict[str, str] | None = None) -> web.Response:
    return web.json_response(body, status=status, headers=headers)


def make_middleware(bind_host: str, token: str, port: int, token_file: Path | None = None, **options: Any) -> Callable[..., Awaitable[web.StreamResponse]]:
    """The middleware of a :class:`Gate` (``options``: the Gate's keyword arguments)."""
    return Gate(bind_host, token, port, token_file, **options).middleware


SECURITY_HEADERS: dict[str, Any] = {
    # Nothing the page loads or connects to may leave this server.
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; media-src 'self' blob:; "
                               "connect-src 'self'; style-src 'self'; script-src 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
