"""The HTTP and websocket server of the UI (aiohttp), running on the component's event loop."""
from __future__ import annotations

import asyncio
import json
import logging
import socket
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from emos.actors.ui import settings as settings_mod
from emos.actors.ui.actions import ActionRunner
from emos.actors.ui.api import Api, check_op_role
from emos.actors.ui.auth import CSRF_KEY, PRINCIPAL_KEY, SECURITY_HEADERS, Gate, Principal, refused
from emos.actors.ui.config import UIConfig
from emos.actors.ui.devices import DeviceStore
from emos.actors.ui.inputs import InputRefused, message_from_page, message_from_upload
from emos.actors.ui.services import InputRunners, ServiceRunner
from emos.actors.ui.streams import Client, Hub, serve_client
from emos.actors.ui.system_view import SystemView
from emos.actors.ui.tokenfile import TokenFileRefused, remove_token_file, write_token_file
from emos.actors.ui.widgets import describe_fields, input_kind
from emos.hosts import is_loopback
from emos.msgs.registry import resolve

log = logging.getLogger("emos.ui")

CSRF_PLACEHOLDER = b"__EMOS_CSRF__"  # in index.html; replaced by the session's CSRF token
STATIC = {"app.js": "application/javascript", "media.js": "application/javascript", "panels.js": "application/javascript", "app.css": "text/css",
          "index.html": "text/html", "favicon.svg": "image/svg+xml", "pair.html": "text/html", "pair.js": "application/javascript",
          "graph.js": "application/javascript", "zones.js": "application/javascript"}
PAGES = ("index.html", "pair.html")  # served at / and /pair, not as /static/...
REVOCATION_CHECK_S = 1.0  # how soon an open websocket of a revoked or expired device token is closed
PAIRING_CHECK_S = 1.0  # how soon an expired pairing code is replaced (and `emos ui pair` shows the new one)


def _dumps(obj: Any) -> str:
    return json.dumps(obj, default=str)


MAX_ZONE_POINTS = 1000


def _zone_edit_args(body: Any) -> dict[str, Any]:
    """The checked fields of a zone edit from the page (ValueError naming the field)."""
    if not isinstance(body, dict):
        raise ValueError("expected a JSON object {op, name, kind, polygon, value}")
    verb = body.get("op")
    if verb not in ("add", "set", "remove"):
        raise ValueError(f"op: must be add, set or remove, got {verb!r}")
    name = body.get("name")
    if not isinstance(name, str) or not name.strip() or len(name) > 64:
        raise ValueError(f"name: a zone name of 1-64 characters, got {name!r}")
    out: dict[str, Any] = {"verb": verb, "name": name.strip()}
    if verb == "remove":
        return out
    kind = body.get("kind")
    if kind is not None and kind not in ("keepout", "speed"):
        raise ValueError(f"kind: must be keepout or speed, got {kind!r}")
    polygon = body.get("polygon")
    point_ok = lambda p: isinstance(p, list) and len(p) == 2 and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in p)  # noqa: E731
    if polygon is not None and (not isinstance(polygon, list) or not 3 <= len(polygon) <= MAX_ZONE_POINTS or not all(map(point_ok, polygon))):
        raise ValueError(f"polygon: 3 to {MAX_ZONE_POINTS} points [x, y] in metres")
    value = body.get("value")
    if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
        raise ValueError(f"value: a number (the speed limit), got {value!r}")
    return {**out, "kind": kind, "polygon": polygon, "value": value}


def bind_socket(host: str, port: int) -> socket.socket:
    """Listen now, so a taken port fails the component's configure with a clear error."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(128)
        sock.setblocking(False)
    except OSError as exc:
        sock.close()
        raise OSError(f"the UI cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    return sock


class UIServer:
    def __init__(self, config: UIConfig, hubs: list[Hub], inputs: dict[str, str], components: dict[str, Any],
                 publish: Callable[[str, Any], None], control_socket: Callable[[str], Path], supervisor_socket: str | None,
                 own_name: str, actions: dict[str, Any] | None = None, action_socket: Callable[[str], Path] | None = None,
                 token_file: Path | None = None, services: dict[str, Any] | None = None, devices_file: Path | None = None,
                 pairing_file: Path | None = None, base_url: str = "", graph: dict[str, Any] | None = None, log_file: Path | None = None,
                 clock: Callable[[], float] = time.time):
        """``token_file``: where the access token is kept (mode 0600) while the UI listens;
        ``devices_file``: the device-token store (no pairing without one); ``pairing_file``: where
        the current pairing code is kept for ``emos ui pair``; ``base_url``: the page's address
        (for the pairing QR code); ``graph``: the system graph (system_view.describe_graph);
        ``log_file``: the run's log, whose tail ``/api/v1/logs`` returns; ``clock``: the wall
        clock pairing codes expire by (injectable for tests)."""
        self.clock = clock
        self._pairing_task: asyncio.Future[None] | None = None
        self.config, self.hubs, self.inputs = config, hubs, inputs
        self.token_file = token_file
        self.devices = DeviceStore(devices_file) if devices_file is not None else None
        self.pairing_file, self.base_url = pairing_file, base_url
        self.components = components  # name -> config object (its class drives the form)
        self.publish, self.control_socket, self.own_name = publish, control_socket, own_name
        self.system = SystemView(supervisor_socket, control_socket, own_name)
        socket_of = action_socket or (lambda name: Path(name))
        self.action_runner = ActionRunner(actions or {}, socket_of)
        self.service_runner = ServiceRunner(services or {}, socket_of)
        self.actions = InputRunners(self.action_runner, self.service_runner)
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ui-encode")
        self.clients: set[Client] = set()
        self._closed = asyncio.Event()
        self._runner: web.AppRunner | None = None
        self._sock: socket.socket | None = None
        self._assets = {name: (resources.files("emos.actors.ui") / "static" / name).read_bytes() for name in STATIC}
        self.published = 0
        self.gate: Gate | None = None
        self.api = Api(self, log_file=log_file, graph=graph)
        self._zone_lock = asyncio.Lock()

    # ------------------------------------------------------------------ lifecycle
    def bind(self) -> None:
        if self._sock is None:
            self._closed.clear()
            self._sock = bind_socket(self.config.host, self.config.port)

    def make_gate(self) -> Gate:
        """The checks of every request (auth.py); refuses to serve off loopback in clear."""
        c = self.config
        if not c.uses_tls() and not is_loopback(c.host):
            raise ValueError(f"the UI on {c.host}:{c.port} would send its tokens across the network in clear: "
                             "use UIConfig.tls='auto' or 'on' (a self-signed certificate is made when none is given), "
                             "or bind it to 127.0.0.1")
        if c.uses_tls() and not (c.certfile and c.keyfile):
            raise ValueError(f"the UI on {c.host}:{c.port} serves HTTPS but has no certificate (UIConfig.certfile, keyfile); "
                             "enable_ui makes one")
        return Gate(c.host, c.token, c.port, self.token_file, devices=self.devices if c.pairing or self.devices else None, tls=c.uses_tls(),
                    allowed_hosts=c.allowed_hosts, failures_per_minute=c.auth_failures_per_minute,
                    pairing_code=c.pairing_code if c.pairing and self.devices is not None else "", pairing_role=c.pairing_role,
                    token_ttl_s=c.token_ttl_h * 3600.0, pairing_file=self.pairing_file, base_url=self.base_url, serve_browser=c.serve_browser,
                    pairing_ttl_s=c.pairing_code_ttl_s, pairing_expires=c.pairing_code_expires, clock=self.clock)

    async def start(self) -> None:
        ssl_context = None
        if self.config.uses_tls():
            from emos.actors.ui.tls import server_context

            ssl_context = server_context(self.config.certfile, self.config.keyfile)
        self.gate = self.make_gate()
        app = web.Application(middlewares=[self.gate.middleware], client_max_size=32 * 2**20)
        app.on_response_prepare.append(self._headers)
        routes = [
            web.get("/api/layout", self._layout), web.post("/api/upload/{topic:.+}", self._upload),
            web.get("/api/settings", self._settings), web.post("/api/settings/{component}", self._apply_settings),
            web.get("/api/system", self._system), web.post("/api/system/{component}/{action}", self._system_action),
            web.get("/api/stats", self._stats), web.get("/api/session", self._session),
            web.get("/api/zones", self._zones), web.post("/api/zones", self._edit_zone),
            *self.api.routes(),
        ]
        if self.config.serve_browser:  # headless: the API only, no page
            routes += [web.get("/", self._index), web.get("/pair", self._pair_page), web.get("/static/{name}", self._static),
                       web.get("/ws", self._ws)]
        app.add_routes(routes)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        assert self._sock is not None
        await web.SockSite(self._runner, self._sock, shutdown_timeout=1.0, ssl_context=ssl_context).start()
        self._write_token_file()
        if self.gate.pairing_code:
            self.gate.current_code()  # a code that expired before the UI came up is replaced now
            self.gate.write_pairing_file()
            self._pairing_task = asyncio.ensure_future(self._renew_pairing_code(self.gate))

    async def _renew_pairing_code(self, gate: Gate) -> None:
        """Replace the pairing code when it expires, so that `emos ui pair` always shows one that works."""
        while not self._closed.is_set():
            gate.current_code()
            await asyncio.sleep(PAIRING_CHECK_S)

    def _write_token_file(self) -> None:
        if self.token_file is None:
            return
        try:
            write_token_file(self.token_file, self.config.token)
        except (TokenFileRefused, OSError) as exc:  # the printed link still works: serve anyway
            log.error("[ui] port %d: %s", self.config.port, exc)

    def close_listener(self) -> None:
        """Synchronous part of stopping: free the port at once."""
        self._closed.set()
        if self._pairing_task is not None:
            self._pairing_task.cancel()
            self._pairing_task = None
        for c in list(self.clients):
            c.dirty.set()
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        for path in (self.token_file, self.pairing_file):
            if path is not None:
                left = remove_token_file(path)
                if left is not None:
                    log.warning("[ui] port %d: %s left in place: it %s", self.config.port, path, left)

    async def stop(self) -> None:
        runner, self._runner = self._runner, None
        if runner is not None and self._sock is not None:
            # Still listening: stop serving before the socket is closed under the server.
            self._closed.set()
            await runner.cleanup()
            runner = None
        self.close_listener()
        self.actions.close()
        if runner is not None:
            try:
                await runner.cleanup()
            except ValueError:  # its socket was closed already (close_listener frees the port at once)
                pass
        self.executor.shutdown(wait=False, cancel_futures=True)

    async def _headers(self, request: web.Request, response: web.StreamResponse) -> None:
        for k, v in SECURITY_HEADERS.items():
            response.headers.setdefault(k, v)

    # ------------------------------------------------------------------ pages
    async def _index(self, request: web.Request) -> web.Response:
        # The session's CSRF token, readable only by script of this origin (see auth.py).
        page = self._assets["index.html"].replace(CSRF_PLACEHOLDER, request[CSRF_KEY].encode())
        return web.Response(body=page, content_type="text/html")

    async def _session(self, request: web.Request) -> web.Response:
        """For scripts: the CSRF token of this session (the session cookie comes with it), and
        who the credential is (the page hides what a viewer may not do)."""
        return web.json_response({"csrf": request[CSRF_KEY], **request[PRINCIPAL_KEY].describe()})

    async def _pair_page(self, request: web.Request) -> web.Response:
        return web.Response(body=self._assets["pair.html"], content_type="text/html")

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in STATIC or name in PAGES:
            raise web.HTTPNotFound(text=f"no asset {name!r}")
        return web.Response(body=self._assets[name], content_type=STATIC[name])

    async def _layout(self, request: web.Request) -> web.Response:
        inputs = []
        for topic, type_name in self.inputs.items():
            entry: dict[str, Any] = {"topic": topic, "type": type_name, "kind": input_kind(type_name)}
            if entry["kind"] == "form":
                entry["fields"] = describe_fields(resolve(type_name))
            inputs.append(entry)
        inputs += self.actions.describe()
        return web.json_response({"title": self.config.title, "outputs": [h.describe() for h in self.hubs], "inputs": inputs,
                                  "components": sorted(self.components), "ui": self.own_name, "zones": bool(self.config.zones_map)})

    async def _stats(self, request: web.Request) -> web.Response:
        return web.json_response({
            "clients": [{"peer": c.peer, "frames_sent": c.frames_sent} for c in self.clients],
            "hubs": [{"topic": h.topic, "received": h.received, "encoded": getattr(h, "encoded_count", None)} for h in self.hubs],
            "published": self.published,
        })

    # ------------------------------------------------------------------ websocket
    async def _ws(self, request: web.Request) -> web.WebSocketResponse:
        principal: Principal = request[PRINCIPAL_KEY]
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4 * 2**20)
        await ws.prepare(request)
        client = Client(ws.send_str, ws.send_bytes, request.remote or "?")
        self.clients.add(client)
        sender = asyncio.ensure_future(serve_client(client, self.hubs, self._closed, self.executor))
        watch = asyncio.ensure_future(self.watch_credential(ws, principal))
        try:
            async for frame in ws:
                if frame.type != WSMsgType.TEXT:
                    continue
                try:
                    request_msg = json.loads(frame.data)
                except ValueError:
                    await ws.send_json({"op": "error", "error": "not JSON"})
                    continue
                op = request_msg.get("op") if isinstance(request_msg, dict) else None
                if op == "ack":
                    client.ack(str(request_msg.get("topic")))
                else:
                    await ws.send_json(await self.handle_op(request_msg, principal, ws, request))
                if sender.done():
                    break
        finally:
            self.clients.discard(client)
            sender.cancel()
            await asyncio.gather(sender, return_exceptions=True)
            await self.end_watch(watch)
            if sender.done() and not sender.cancelled() and sender.exception() is not None:
                log.warning("[ui] page %s: sending failed: %s", client.peer, sender.exception())
        return ws

    async def handle_op(self, msg: Any, principal: Principal, ws: web.WebSocketResponse, request: web.Request) -> dict[str, Any]:
        """One websocket request (publish, goal, cancel, call), after the role check."""
        op = msg.get("op") if isinstance(msg, dict) else None
        rid = msg.get("id") if isinstance(msg, dict) else None
        why = check_op_role(principal, str(op))
        if why is not None:
            refused("a viewer's websocket op", request, why)
            return {"op": "result", "id": rid, "ok": False, "error": why}
        assert isinstance(msg, dict)
        if op == "publish":
            return self.publish_value(msg.get("topic"), msg.get("value"), rid)
        if op in ("goal", "call"):
            return self.actions.send(msg, lambda m: ws.send_json(m, dumps=_dumps))
        if op == "cancel":
            return self.actions.cancel(msg)
        return {"op": "error", "id": rid, "error": f"unknown op {op!r}"}

    async def watch_credential(self, ws: web.WebSocketResponse, principal: Principal) -> None:
        """Close the websocket of a device token once it is revoked or expires (close code 4401)."""
        while not ws.closed and self.gate is not None:
            await asyncio.sleep(REVOCATION_CHECK_S)
            if not self.gate.still_valid(principal):
                log.warning("[ui] closing the websocket of %s: its token was revoked or has expired", principal)
                # Shielded: the handler's loop ends when the close completes, and its clean-up
                # must not cut the closing handshake short (the client would see 1006, not why).
                await asyncio.shield(ws.close(code=4401, message=b"token revoked or expired"))
                return

    @staticmethod
    async def end_watch(watch: asyncio.Future[None]) -> None:
        """Stop a websocket's credential watch, letting a close it started finish."""
        if not watch.done():
            watch.cancel()
        await asyncio.gather(watch, return_exceptions=True)

    def publish_value(self, topic: Any, value: Any, request_id: Any = None) -> dict[str, Any]:
        rid = request_id
        type_name = self.inputs.get(str(topic))
        if type_name is None:
            return {"op": "result", "id": rid, "ok": False, "error": f"{topic!r} is not an input of this page"}
        try:
            msg = message_from_page(str(topic), type_name, value)
        except (InputRefused, TypeError, ValueError) as exc:  # a field's own check (a Float32 out of range) included
            return {"op": "result", "id": rid, "ok": False, "error": str(exc) if isinstance(exc, InputRefused) else f"{topic}: {exc}"}
        try:
            self.publish(str(topic), msg)
        except Exception as exc:  # e.g. the component is not active: say so, keep serving
            log.error("[ui] publishing on %s failed: %s", topic, exc)
            return {"op": "result", "id": rid, "ok": False, "error": f"{topic}: {exc}", "unavailable": True}
        self.published += 1
        return {"op": "result", "id": rid, "ok": True}

    async def _upload(self, request: web.Request) -> web.Response:
        topic = "/" + request.match_info["topic"].lstrip("/")
        type_name = self.inputs.get(topic) or self.inputs.get(request.match_info["topic"])
        if type_name is None:
            return web.json_response({"ok": False, "error": f"{topic!r} is not an input of this page"}, status=404)
        return await self.upload_to(topic, type_name, request)

    async def upload_to(self, topic: str, type_name: str, request: web.Request) -> web.Response:
        body = await request.read()
        try:
            msg = await asyncio.get_running_loop().run_in_executor(self.executor, message_from_upload, topic, type_name, body)
            self.publish(topic, msg)
        except InputRefused as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=400)
        self.published += 1
        return web.json_response({"ok": True})

    # ------------------------------------------------------------------ settings
    async def _settings(self, request: web.Request) -> web.Response:
        out = []
        for name, config in sorted(self.components.items()):
            entry: dict[str, Any] = {"component": name, "type": type(config).__name__, "fields": settings_mod.describe_config(config)}
            try:
                entry["values"] = (await settings_mod.read_config(self.control_socket(name)))["config"]
            except Exception as exc:
                entry["values"], entry["error"] = config.asdict(), f"not reachable ({exc}); showing the recipe's values"
            out.append(entry)
        return web.json_response(out, dumps=lambda o: json.dumps(o, default=str))

    async def _apply_settings(self, request: web.Request) -> web.Response:
        name = request.match_info["component"]
        config = self.components.get(name)
        if config is None:
            return web.json_response({"ok": False, "error": f"no component {name!r}; components: {sorted(self.components)}"}, status=404)
        try:
            raw = await request.json()
        except ValueError:
            return web.json_response({"ok": False, "error": "expected a JSON object of parameter values"}, status=400)
        if not isinstance(raw, dict) or not raw:
            return web.json_response({"ok": False, "error": "expected a JSON object of parameter values"}, status=400)
        fields = {f["name"]: f for f in settings_mod.describe_config(config)}
        try:
            values = {}
            for key, value in raw.items():
                if key not in fields:
                    raise settings_mod.SettingRefused(f"{type(config).__name__} has no parameter {key!r}")
                values[key] = settings_mod.convert_value(fields[key], value)
            new = await settings_mod.apply_config_change(self.control_socket(name), name, values)
        except settings_mod.SettingRefused as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=400)
        except (ConnectionError, TimeoutError) as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=503)
        log.info("[ui] %s: settings changed from the page: %s", name, values)
        return web.json_response({"ok": True, "values": new}, dumps=lambda o: json.dumps(o, default=str))

    # ------------------------------------------------------------------ zones
    def _zones_map(self) -> Path | None:
        return Path(self.config.zones_map).expanduser() if self.config.zones_map else None

    async def _zones(self, request: web.Request) -> web.Response:
        """The keepout and speed zones of ``UIConfig.zones_map`` (what `emos map zones list` shows)."""
        path = self._zones_map()
        if path is None:
            return web.json_response({"ok": False, "error": "this UI edits no zones (UIConfig.zones_map)"}, status=404)
        from emos.actors.nav.costmap.mask_io import load_zones

        try:
            zones, speed_type = await asyncio.get_running_loop().run_in_executor(None, load_zones, path)
        except (ValueError, OSError) as exc:
            return web.json_response({"ok": False, "error": f"zones of {path}: {exc}"}, status=503)
        return web.json_response({"ok": True, "map": str(path), "speed_type": speed_type, "zones": [z.to_dict() for z in zones]})

    async def _edit_zone(self, request: web.Request) -> web.Response:
        """``{"op": "add"|"set"|"remove", "name", "kind", "polygon": [[x, y], ...], "value"}``
        (operators: the gate): saved with the code `emos map zones` uses (mask_io.edit_zone)."""
        path = self._zones_map()
        if path is None:
            return web.json_response({"ok": False, "error": "this UI edits no zones (UIConfig.zones_map)"}, status=404)
        try:
            body = await request.json()
        except ValueError:
            body = None
        try:
            args = _zone_edit_args(body)
        except ValueError as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=422)
        from emos.actors.nav.costmap.mask_io import edit_zone

        async with self._zone_lock:  # one edit at a time: each is a read-modify-write of the masks
            try:
                written = await asyncio.get_running_loop().run_in_executor(None, lambda: edit_zone(path, **args))
            except (ValueError, OSError) as exc:  # FilterMaskError and MapFileError are ValueErrors
                return web.json_response({"ok": False, "error": str(exc)}, status=422)
        log.info("[ui] zones of %s: %s %r by %s", path, args["verb"], args["name"], request[PRINCIPAL_KEY])
        return web.json_response({"ok": True, "written": [str(p) for p in written]})

    # ------------------------------------------------------------------ system
    async def _system(self, request: web.Request) -> web.Response:
        try:
            return web.json_response(await self.system.snapshot())
        except Exception as exc:
            return web.json_response({"error": f"supervisor not reachable: {exc}"}, status=503)

    async def _system_action(self, request: web.Request) -> web.Response:
        name, action = request.match_info["component"], request.match_info["action"]
        try:
            detail = await self.system.act(name, action, known=set(self.components) | {self.own_name})
        except ValueError as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=400)
        except Exception as exc:
            return web.json_response({"ok": False, "error": f"{name}: {action} failed: {exc}"}, status=503)
        log.info("[ui] %s: %s requested from the page", name, action)
        return web.json_response({"ok": True, "detail": detail, "t": time.time()})
