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
from emos.actors.ui.auth import CSRF_KEY, SECURITY_HEADERS, make_middleware
from emos.actors.ui.config import UIConfig
from emos.actors.ui.inputs import InputRefused, message_from_page, message_from_upload
from emos.actors.ui.services import with_services
from emos.actors.ui.streams import Client, Hub, serve_client
from emos.actors.ui.system_view import SystemView
from emos.actors.ui.tokenfile import TokenFileRefused, remove_token_file, write_token_file
from emos.actors.ui.widgets import describe_fields, input_kind
from emos.msgs.registry import resolve

log = logging.getLogger("emos.ui")

CSRF_PLACEHOLDER = b"__EMOS_CSRF__"  # in index.html; replaced by the session's CSRF token
STATIC = {"app.js": "application/javascript", "media.js": "application/javascript", "panels.js": "application/javascript", "app.css": "text/css", "index.html": "text/html", "favicon.svg": "image/svg+xml"}


def _dumps(obj: Any) -> str:
    return json.dumps(obj, default=str)


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
                 token_file: Path | None = None, services: dict[str, Any] | None = None):
        """``token_file``: where the access token is kept (mode 0600) while the UI listens."""
        self.config, self.hubs, self.inputs = config, hubs, inputs
        self.token_file = token_file
        self.components = components  # name -> config object (its class drives the form)
        self.publish, self.control_socket, self.own_name = publish, control_socket, own_name
        self.system = SystemView(supervisor_socket, control_socket, own_name)
        socket_of = action_socket or (lambda name: Path(name))
        self.actions = with_services(ActionRunner(actions or {}, socket_of), services, socket_of)
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ui-encode")
        self.clients: set[Client] = set()
        self._closed = asyncio.Event()
        self._runner: web.AppRunner | None = None
        self._sock: socket.socket | None = None
        self._assets = {name: (resources.files("emos.actors.ui") / "static" / name).read_bytes() for name in STATIC}
        self.published = 0

    # ------------------------------------------------------------------ lifecycle
    def bind(self) -> None:
        if self._sock is None:
            self._closed.clear()
            self._sock = bind_socket(self.config.host, self.config.port)

    async def start(self) -> None:
        guard = make_middleware(self.config.host, self.config.token, self.config.port, self.token_file)
        app = web.Application(middlewares=[guard], client_max_size=32 * 2**20)
        app.on_response_prepare.append(self._headers)
        app.add_routes([
            web.get("/", self._index), web.get("/static/{name}", self._static), web.get("/api/layout", self._layout),
            web.get("/ws", self._ws), web.post("/api/upload/{topic:.+}", self._upload),
            web.get("/api/settings", self._settings), web.post("/api/settings/{component}", self._apply_settings),
            web.get("/api/system", self._system), web.post("/api/system/{component}/{action}", self._system_action),
            web.get("/api/stats", self._stats), web.get("/api/session", self._session),
        ])
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        assert self._sock is not None
        await web.SockSite(self._runner, self._sock, shutdown_timeout=1.0).start()
        self._write_token_file()

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
        for c in list(self.clients):
            c.dirty.set()
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self.token_file is not None:
            left = remove_token_file(self.token_file)
            if left is not None:
                log.warning("[ui] port %d: token file %s left in place: it %s", self.config.port, self.token_file, left)

    async def stop(self) -> None:
        self.close_listener()
        self.actions.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
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
        """For scripts: the CSRF token of this session (the session cookie comes with it)."""
        return web.json_response({"csrf": request[CSRF_KEY]})

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in STATIC or name == "index.html":
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
                                  "components": sorted(self.components), "ui": self.own_name})

    async def _stats(self, request: web.Request) -> web.Response:
        return web.json_response({
            "clients": [{"peer": c.peer, "frames_sent": c.frames_sent} for c in self.clients],
            "hubs": [{"topic": h.topic, "received": h.received, "encoded": getattr(h, "encoded_count", None)} for h in self.hubs],
            "published": self.published,
        })

    # ------------------------------------------------------------------ websocket
    async def _ws(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4 * 2**20)
        await ws.prepare(request)
        client = Client(ws.send_str, ws.send_bytes, request.remote or "?")
        self.clients.add(client)
        sender = asyncio.ensure_future(serve_client(client, self.hubs, self._closed, self.executor))
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
                elif op == "publish":
                    await ws.send_json(self._publish_from_page(request_msg))
                elif op == "goal":
                    await ws.send_json(self.actions.send(request_msg, lambda m: ws.send_json(m, dumps=_dumps)))
                elif op == "cancel":
                    await ws.send_json(self.actions.cancel(request_msg))
                else:
                    await ws.send_json({"op": "error", "error": f"unknown op {op!r}"})
                if sender.done():
                    break
        finally:
            self.clients.discard(client)
            sender.cancel()
            await asyncio.gather(sender, return_exceptions=True)
            if sender.done() and not sender.cancelled() and sender.exception() is not None:
                log.warning("[ui] page %s: sending failed: %s", client.peer, sender.exception())
        return ws

    def _publish_from_page(self, req: dict[str, Any]) -> dict[str, Any]:
        rid, topic = req.get("id"), req.get("topic")
        type_name = self.inputs.get(str(topic))
        if type_name is None:
            return {"op": "result", "id": rid, "ok": False, "error": f"{topic!r} is not an input of this page"}
        try:
            msg = message_from_page(str(topic), type_name, req.get("value"))
            self.publish(str(topic), msg)
        except InputRefused as exc:
            return {"op": "result", "id": rid, "ok": False, "error": str(exc)}
        except Exception as exc:  # e.g. the component is not active: say so, keep serving
            log.error("[ui] publishing on %s failed: %s", topic, exc)
            return {"op": "result", "id": rid, "ok": False, "error": f"{topic}: {exc}"}
        self.published += 1
        return {"op": "result", "id": rid, "ok": True}

    async def _upload(self, request: web.Request) -> web.Response:
        topic = "/" + request.match_info["topic"].lstrip("/")
        type_name = self.inputs.get(topic) or self.inputs.get(request.match_info["topic"])
        if type_name is None:
            return web.json_response({"ok": False, "error": f"{topic!r} is not an input of this page"}, status=404)
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
