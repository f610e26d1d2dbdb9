"""The REST and WebSocket API under ``/api/v1/`` (its OpenAPI document: ``/api/v1/openapi.json``).

Every body is checked against the schema the document publishes (:mod:`emos.actors.ui.openapi`)
before anything happens: a wrong type is a 422 naming the field, and nothing is published,
called or sent. Roles are enforced by the gate (auth.py) for HTTP and here for websocket ops.
"""
from __future__ import annotations

import asyncio
import collections
import json
import logging
import re
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiohttp import WSMsgType, web

from emos.actors.ui import openapi
from emos.actors.ui import settings as settings_mod
from emos.actors.ui.auth import CSRF_KEY, PRINCIPAL_KEY, Principal, client_of, refused
from emos.actors.ui.inputs import InputRefused, goal_from_page
from emos.actors.ui.services import service_key
from emos.actors.ui.system_view import ACTIONS as SYSTEM_ACTIONS
from emos.actors.ui.widgets import input_kind

if TYPE_CHECKING:
    from emos.actors.ui.server import UIServer

log = logging.getLogger("emos.ui")

OPERATOR_OPS = ("publish", "goal", "cancel", "call")
MAX_RATE, MIN_RATE = 100.0, 0.01
GOALS_KEPT = 256
FEEDBACK_KEPT = 20
_GOAL_ID = re.compile(r"^[0-9a-f]{32}$")


def _dumps(obj: Any) -> str:
    return json.dumps(obj, default=str)


def _error(status: int, error: str, field: str | None = None) -> web.Response:
    body: dict[str, Any] = {"ok": False, "error": error}
    if field is not None:
        body["field"] = field
    return web.json_response(body, status=status)


class GoalBook:
    """What became of the goals sent through the REST API: state, last feedback, result."""

    def __init__(self) -> None:
        self.goals: collections.OrderedDict[str, dict[str, Any]] = collections.OrderedDict()

    def sink(self, action: str) -> Any:
        async def record(message: dict[str, Any]) -> None:
            goal_id = message.get("goal_id")
            if not goal_id:
                return
            entry = self.goals.setdefault(goal_id, {"action": action, "goal_id": goal_id, "state": "sent", "feedback": [], "result": None})
            self.goals.move_to_end(goal_id)
            while len(self.goals) > GOALS_KEPT:
                self.goals.popitem(last=False)
            state = message.get("state")
            if state == "feedback":
                entry["feedback"] = (entry["feedback"] + [message.get("value")])[-FEEDBACK_KEPT:]
            elif state in ("succeeded", "canceled", "failed"):
                entry["state"], entry["result"], entry["t_done"] = state, message.get("value"), time.time()
            elif state == "sent":
                entry["state"] = "running"
        return record


def check_op_role(principal: Principal | None, op: str) -> str | None:
    """Why ``principal`` may not send websocket op ``op`` (``None``: it may)."""
    if op in OPERATOR_OPS and (principal is None or not principal.may("operator")):
        return f"{principal or 'this connection'} may only watch: {op!r} needs the operator role"
    return None


class Api:
    def __init__(self, server: UIServer, log_file: Path | None = None, graph: dict[str, Any] | None = None):
        self.server = server
        self.log_file = log_file
        self.graph = graph or {"components": [], "topics": [], "events": []}
        self.book = GoalBook()
        self._doc: dict[str, Any] | None = None

    def routes(self) -> list[web.RouteDef]:
        p = "/api/v1"
        return [
            web.get(f"{p}/openapi.json", self.openapi), web.get(f"{p}/session", self.session),
            web.get(f"{p}/inputs", self.list_inputs), web.post(p + "/inputs/{topic:.+}", self.publish),
            web.post(p + "/services/{name:.+}", self.call_service),
            web.post(p + "/actions/{name:.+}/goals", self.send_goal),
            web.get(p + "/actions/{name:.+}/goals/{goal_id}", self.goal_state),
            web.post(p + "/actions/{name:.+}/goals/{goal_id}/cancel", self.cancel_goal),
            web.get(f"{p}/outputs", self.list_outputs), web.get(p + "/outputs/{topic:.+}/latest", self.latest),
            web.get(f"{p}/system", self.system), web.get(f"{p}/graph", self.graph_view), web.get(f"{p}/logs", self.logs),
            web.get(f"{p}/settings", self.list_settings), web.post(p + "/settings/{component}", self.change_settings),
            web.post(p + "/components/{component}/{action}", self.component_action),
            web.get(f"{p}/ws", self.ws),
        ]

    # ------------------------------------------------------------------ meta
    def document(self) -> dict[str, Any]:
        if self._doc is None:
            s = self.server
            self._doc = openapi.document(s.config.title, s.inputs, s.action_runner.actions, s.service_runner.services,
                                         [h.describe() for h in s.hubs], settings=self._fields(), system_actions=SYSTEM_ACTIONS)
        return self._doc

    async def openapi(self, request: web.Request) -> web.Response:
        return web.json_response(self.document())

    async def session(self, request: web.Request) -> web.Response:
        principal: Principal = request[PRINCIPAL_KEY]
        return web.json_response({**principal.describe(), "csrf": request[CSRF_KEY]})

    async def list_inputs(self, request: web.Request) -> web.Response:
        s = self.server
        return web.json_response({
            "inputs": [{"topic": t, "type": ty, "schema": openapi.input_schema(ty) if input_kind(ty) not in openapi.RAW_TYPES else None}
                       for t, ty in s.inputs.items()],
            "actions": [{"name": n, "goal": a.goal_type.__name__, "feedback": a.feedback_type.__name__, "result": a.result_type.__name__,
                         "schema": openapi.goal_schema(a.goal_type)} for n, a in s.action_runner.actions.items()],
            "services": [{"name": n, "request": v.request_type.__name__, "response": v.response_type.__name__,
                          "schema": openapi.message_schema(v.request_type)} for n, v in s.service_runner.services.items()],
        })

    async def _body(self, request: web.Request, key: str, schema: dict[str, Any]) -> Any:
        """The checked ``key`` of the JSON body, or raise a 4xx response naming what is wrong."""
        if request.content_type != "application/json":
            raise web.HTTPUnsupportedMediaType(text=_dumps({"ok": False, "error": "the body must be JSON ('Content-Type: application/json')"}),
                                               content_type="application/json")
        try:
            body = json.loads(await request.read() or b"null")
        except (ValueError, UnicodeDecodeError) as exc:
            raise web.HTTPBadRequest(text=_dumps({"ok": False, "error": f"the body is not JSON: {exc}", "field": "body"}),
                                     content_type="application/json") from None
        try:
            openapi.check(openapi.envelope(key, schema), body)
        except openapi.RequestInvalid as exc:
            raise web.HTTPUnprocessableEntity(text=_dumps({"ok": False, "error": str(exc), "field": exc.field}),
                                              content_type="application/json") from None
        return body[key]

    # ------------------------------------------------------------------ inputs
    async def publish(self, request: web.Request) -> web.Response:
        s = self.server
        name = request.match_info["topic"].lstrip("/")
        topic = next((t for t in s.inputs if t.lstrip("/") == name), None)
        if topic is None:
            return _error(404, f"{name!r} is not an input of this UI; inputs: {', '.join(s.inputs) or 'none'}")
        type_name = s.inputs[topic]
        if input_kind(type_name) in openapi.RAW_TYPES:
            return await s.upload_to(topic, type_name, request)
        value = await self._body(request, "value", openapi.input_schema(type_name))
        result = s.publish_value(topic, value, request_id=None)
        if not result["ok"]:
            status = 503 if result.get("unavailable") else 422
            return _error(status, result["error"], "value" if status == 422 else None)
        return web.json_response({"ok": True})

    async def call_service(self, request: web.Request) -> web.Response:
        runner = self.server.service_runner
        key = service_key(request.match_info["name"])
        service = runner.services.get(key)
        if service is None:
            return _error(404, f"{key!r} is not a service of this UI; services: {', '.join(runner.services) or 'none'}")
        value = await self._body(request, "request", openapi.message_schema(service.request_type))
        try:
            msg = goal_from_page(key, service.request_type, value)
        except (InputRefused, TypeError, ValueError) as exc:
            return _error(422, str(exc), "request")
        state, response = await runner.call_once(key, service, msg)
        if state == "unreachable":
            return _error(503, f"service {key}: {response}")
        return web.json_response({"ok": state == "succeeded", "response": response}, dumps=_dumps)

    # ------------------------------------------------------------------ actions
    def _action(self, request: web.Request) -> tuple[str, Any]:
        runner = self.server.action_runner
        name = request.match_info["name"].strip("/")
        key = next((k for k in runner.actions if k.strip("/") == name), None)
        if key is None:
            raise web.HTTPNotFound(text=_dumps({"ok": False, "error": f"{name!r} is not an action of this UI; actions: "
                                                                    f"{', '.join(runner.actions) or 'none'}"}), content_type="application/json")
        return key, runner.actions[key]

    async def send_goal(self, request: web.Request) -> web.Response:
        key, action = self._action(request)
        goal = await self._body(request, "goal", openapi.goal_schema(action.goal_type))
        try:
            answer = self.server.action_runner.send({"topic": key, "value": goal}, self.book.sink(key))
        except (TypeError, ValueError) as exc:  # a goal field's own check
            return _error(422, f"{key}: {exc}", "goal")
        if not answer.get("ok"):
            return _error(422, str(answer.get("error")), "goal")
        self.book.goals.setdefault(answer["goal_id"], {"action": key, "goal_id": answer["goal_id"], "state": "sent", "feedback": [], "result": None})
        return web.json_response({"ok": True, "goal_id": answer["goal_id"], "state": "sent"}, status=202)

    def _goal(self, request: web.Request, key: str) -> dict[str, Any]:
        goal_id = request.match_info["goal_id"]
        entry = self.book.goals.get(goal_id) if _GOAL_ID.match(goal_id) else None
        if entry is None or entry["action"] != key:
            raise web.HTTPNotFound(text=_dumps({"ok": False, "error": f"no goal {goal_id[:40]!r} of {key} (goals are kept while they are among the last {GOALS_KEPT})"}),
                                   content_type="application/json")
        return entry

    async def goal_state(self, request: web.Request) -> web.Response:
        key, _ = self._action(request)
        return web.json_response(self._goal(request, key), dumps=_dumps)

    async def cancel_goal(self, request: web.Request) -> web.Response:
        key, _ = self._action(request)
        entry = self._goal(request, key)
        running = self.server.action_runner._running.get(key)
        if entry["state"] in ("succeeded", "canceled", "failed") or running is None or running[0] != entry["goal_id"]:
            return _error(409, f"goal {entry['goal_id']} of {key} is not running (state {entry['state']})")
        answer = self.server.action_runner.cancel({"topic": key})
        if not answer.get("ok"):
            return _error(409, str(answer.get("error")))
        return web.json_response({"ok": True}, status=202)

    # ------------------------------------------------------------------ settings and lifecycle
    def _fields(self) -> dict[str, list[dict[str, Any]]]:
        return {name: settings_mod.describe_config(config) for name, config in self.server.components.items()}

    def _component(self, request: web.Request, known: Any) -> str:
        name = request.match_info["component"]
        if name not in known:
            raise web.HTTPNotFound(text=_dumps({"ok": False, "error": f"no component {name[:80]!r}; components: {', '.join(sorted(known)) or 'none'}",
                                                "field": "component"}), content_type="application/json")
        return name

    async def list_settings(self, request: web.Request) -> web.Response:
        """Every component's form, current values (from the running component) and change schema."""
        out = []
        for name, fields in sorted(self._fields().items()):
            entry: dict[str, Any] = {"component": name, "type": type(self.server.components[name]).__name__, "fields": fields,
                                     "schema": openapi.settings_schema(fields)}
            try:
                entry["values"] = (await settings_mod.read_config(self.server.control_socket(name)))["config"]
            except Exception as exc:  # not running (yet): the recipe's values, said so
                entry["values"], entry["error"] = self.server.components[name].asdict(), f"not reachable ({exc}); the recipe's values"
            out.append(entry)
        return web.json_response({"components": out}, dumps=_dumps)

    async def change_settings(self, request: web.Request) -> web.Response:
        """``{"values": {parameter: value}}``: checked against the component's schema here (types,
        ranges, choices: 422 naming the parameter), then by the component itself, all or nothing."""
        name = self._component(request, self.server.components)
        fields = {f["name"]: f for f in settings_mod.describe_config(self.server.components[name])}
        raw = await self._body(request, "values", {"type": "object"})
        for key in raw:
            if key in fields and not fields[key].get("editable", True):
                return _error(422, f"body.values.{key}: {name}'s {key} is read-only here (a {fields[key]['kind']} value); "
                                   "change it in the recipe or a config file", f"body.values.{key}")
        values = await self._body_checked(raw, "values", openapi.settings_schema(list(fields.values())))
        try:
            converted = {key: settings_mod.convert_value(fields[key], value) for key, value in values.items()}
            new = await settings_mod.apply_config_change(self.server.control_socket(name), name, converted)
        except settings_mod.SettingRefused as exc:  # the component's own validator
            field = f"body.values.{next(iter(values))}" if len(values) == 1 else "body.values"
            return _error(422, str(exc), field)
        except (ConnectionError, TimeoutError) as exc:
            return _error(503, str(exc))
        log.info("[ui] %s: settings changed through the API by %s: %s", name, request[PRINCIPAL_KEY], converted)
        return web.json_response({"ok": True, "values": new}, dumps=_dumps)

    async def _body_checked(self, body: Any, key: str, schema: dict[str, Any]) -> Any:
        try:
            openapi.check(schema, body, f"body.{key}")
        except openapi.RequestInvalid as exc:
            raise web.HTTPUnprocessableEntity(text=_dumps({"ok": False, "error": str(exc), "field": exc.field}),
                                              content_type="application/json") from None
        return body

    async def component_action(self, request: web.Request) -> web.Response:
        """Start (activate), stop (deactivate) or restart a component."""
        s = self.server
        action = request.match_info["action"]
        if action not in SYSTEM_ACTIONS:
            return _error(404, f"no action {action[:40]!r} for components; actions: {', '.join(SYSTEM_ACTIONS)}", "action")
        name = self._component(request, set(s.components) | {s.own_name})
        if name == s.own_name and action != "restart":
            return _error(409, f"the UI cannot {action} itself (it would stop answering); restart it instead")
        if request.can_read_body and request.content_type != "application/json":
            return _error(415, "the body, if any, must be JSON ('Content-Type: application/json')")
        try:
            detail = await s.system.act(name, action, known=set(s.components) | {s.own_name})
        except ValueError as exc:
            return _error(409, str(exc))
        except Exception as exc:  # the component or the supervisor is not reachable
            return _error(503, f"{name}: {action} failed: {exc}")
        log.info("[ui] %s: %s requested through the API by %s", name, action, request[PRINCIPAL_KEY])
        return web.json_response({"ok": True, "detail": detail, "t": time.time()})

    # ------------------------------------------------------------------ outputs and system
    async def list_outputs(self, request: web.Request) -> web.Response:
        return web.json_response({"outputs": [h.describe() for h in self.server.hubs]})

    async def latest(self, request: web.Request) -> web.Response:
        name = request.match_info["topic"].lstrip("/")
        hub = next((h for h in self.server.hubs if h.topic.lstrip("/") == name), None)
        if hub is None:
            return _error(404, f"{name!r} is not an output of this UI")
        return web.json_response(hub.latest(), dumps=_dumps)

    async def system(self, request: web.Request) -> web.Response:
        try:
            return web.json_response(await self.server.system.snapshot(), dumps=_dumps)
        except Exception as exc:
            return _error(503, f"supervisor not reachable: {exc}")

    async def graph_view(self, request: web.Request) -> web.Response:
        return web.json_response(self.graph, dumps=_dumps)

    async def logs(self, request: web.Request) -> web.Response:
        try:
            since = float(request.query.get("since", "0"))
            lines = int(request.query.get("lines", "200"))
            if not (0 <= lines <= 5000) or since != since:
                raise ValueError
        except ValueError:
            return _error(400, "since must be a number (UNIX time) and lines a whole number in [0, 5000]", "lines" if "lines" in request.query else "since")
        events: Any = []
        try:
            events = await self.server.system.events(since)
        except Exception as exc:
            events = {"error": f"supervisor not reachable: {exc}"}
        return web.json_response({"events": events, "log": str(self.log_file) if self.log_file else None,
                                  "lines": await asyncio.get_running_loop().run_in_executor(None, _tail, self.log_file, lines)}, dumps=_dumps)

    # ------------------------------------------------------------------ websocket
    async def ws(self, request: web.Request) -> web.WebSocketResponse:
        """Streams at the client's rate: ``{"op": "subscribe", "topic", "rate"}`` ->
        ``{"op": "sample", "topic", "seq", "stamp", "value"}`` at most ``rate`` times a second
        while the topic has news; also publish, goal, cancel and call (operators)."""
        s = self.server
        principal: Principal = request[PRINCIPAL_KEY]
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4 * 2**20)
        await ws.prepare(request)
        subs: dict[str, asyncio.Task[None]] = {}
        watch = asyncio.ensure_future(s.watch_credential(ws, principal))
        try:
            async for frame in ws:
                if frame.type != WSMsgType.TEXT:
                    continue
                try:
                    msg = json.loads(frame.data)
                except ValueError:
                    await ws.send_json({"op": "error", "error": "not JSON"})
                    continue
                op = msg.get("op") if isinstance(msg, dict) else None
                if op == "subscribe":
                    await ws.send_json(self._subscribe(ws, msg, subs))
                elif op == "unsubscribe":
                    task = subs.pop(str(msg.get("topic", "")).lstrip("/"), None)
                    if task is not None:
                        task.cancel()
                    await ws.send_json({"op": "result", "id": msg.get("id"), "ok": task is not None})
                else:
                    await ws.send_json(await s.handle_op(msg, principal, ws, request))
        finally:
            for task in subs.values():
                task.cancel()
            await asyncio.gather(*subs.values(), return_exceptions=True)
            await s.end_watch(watch)
        return ws

    def _subscribe(self, ws: web.WebSocketResponse, msg: dict[str, Any], subs: dict[str, asyncio.Task[None]]) -> dict[str, Any]:
        rid, name = msg.get("id"), str(msg.get("topic", "")).lstrip("/")
        hub = next((h for h in self.server.hubs if h.topic.lstrip("/") == name), None)
        if hub is None:
            return {"op": "result", "id": rid, "ok": False, "error": f"{name!r} is not an output of this UI", "field": "topic"}
        rate = msg.get("rate", 1.0)
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not MIN_RATE <= rate <= MAX_RATE:
            return {"op": "result", "id": rid, "ok": False, "error": f"rate: a number of Hz in [{MIN_RATE}, {MAX_RATE}], got {rate!r}", "field": "rate"}
        old = subs.pop(name, None)
        if old is not None:
            old.cancel()
        subs[name] = asyncio.ensure_future(self._stream(ws, hub, float(rate)))
        return {"op": "result", "id": rid, "ok": True}

    async def _stream(self, ws: web.WebSocketResponse, hub: Any, rate: float) -> None:
        sent = -1
        period = 1.0 / rate
        try:
            while not ws.closed:
                if hub.seq != sent:
                    sample = hub.latest()
                    sent = hub.seq
                    await ws.send_str(_dumps({"op": "sample", **sample}))
                await asyncio.sleep(period)
        except (ConnectionError, RuntimeError):
            pass  # the client went away


def _tail(path: Path | None, lines: int) -> list[str]:
    if path is None or lines == 0:
        return []
    try:
        with open(path, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - 256 * lines - 4096))
            data = f.read().decode("utf-8", "replace")
    except OSError:
        return []
    return data.splitlines()[-lines:]


__all__ = ["Api", "check_op_role", "client_of", "refused"]
