"""The API's OpenAPI 3.1 document and the JSON Schemas of what it takes, with the checker the
handlers use: a request that does not fit is refused (422) with the field named, before
anything is published or called.

Schemas are derived from the message classes (their attrs fields and field kinds), so the
document always matches the recipe's inputs, actions and services.
"""
from __future__ import annotations

import math
from typing import Any

import attrs

from emos.actors.ui.inputs import goal_field
from emos.actors.ui.widgets import input_kind
from emos.errors import EmosError
from emos.msgs.registry import resolve

_INT_BOUNDS = {"Int32": (-(2**31), 2**31 - 1), "Int64": (-(2**63), 2**63 - 1), "UInt8": (0, 255)}
_PRIMITIVE = {"float": {"type": "number"}, "int": {"type": "integer"}, "bool": {"type": "boolean"}, "str": {"type": "string"}}
GOAL_POINT = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "yaw": {"type": "number"},
                                               "frame_id": {"type": "string"}},
              "required": ["x", "y"], "additionalProperties": False, "description": "a point on the map, metres (and radians)"}
RAW_TYPES = {"audio": ["audio/wav"], "image": ["image/png", "image/jpeg", "application/octet-stream"]}
MAX_DEPTH = 8


class RequestInvalid(EmosError, ValueError):
    """A request body that does not fit its schema; ``field`` is the path of the offending part."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field = field


# ---------------------------------------------------------------------- schemas
def message_schema(cls: type, depth: int = 0) -> dict[str, Any]:
    """The JSON Schema of message class ``cls`` as ``codec.from_builtin`` takes it (fields optional)."""
    if depth > MAX_DEPTH:
        return {"type": "object"}
    props: dict[str, Any] = {}
    for f in attrs.fields(cls):
        meta = f.metadata or {}
        kind = meta.get("kind")
        nested = meta.get("cls")
        if kind == "primitive":
            props[f.name] = dict(_PRIMITIVE.get(str(f.type), {}))
        elif kind == "array":
            props[f.name] = {"type": "array", "items": {"type": "number"}, "maxItems": 1 << 20}
        elif kind == "message" and nested is not None:
            props[f.name] = message_schema(nested(), depth + 1)
        elif kind == "optional_message" and nested is not None:
            props[f.name] = {"anyOf": [message_schema(nested(), depth + 1), {"type": "null"}]}
        elif kind == "message_list" and nested is not None:
            props[f.name] = {"type": "array", "items": message_schema(nested(), depth + 1), "maxItems": 10000}
        elif kind == "str_list":
            props[f.name] = {"type": "array", "items": {"type": "string"}, "maxItems": 10000}
        else:
            props[f.name] = {}
    return {"type": "object", "title": cls.__name__, "properties": props, "additionalProperties": False}


def input_schema(type_name: str) -> dict[str, Any]:
    """The schema of ``value`` for an input topic of ``type_name`` (see inputs.message_from_page)."""
    kind = input_kind(type_name)
    if kind == "text":
        return {"type": "string", "maxLength": 1 << 20}
    if kind == "bool":
        return {"type": "boolean"}
    if kind == "number":
        if type_name in _INT_BOUNDS:
            lo, hi = _INT_BOUNDS[type_name]
            return {"type": "integer", "minimum": lo, "maximum": hi}
        return {"type": "number"}
    if kind == "goal":
        return GOAL_POINT
    return message_schema(resolve(type_name))


def settings_schema(fields: list[dict[str, Any]]) -> dict[str, Any]:
    """The schema of ``values`` for a component's settings change: its editable parameters
    (settings.describe_config), each with its type, range and choices; at least one."""
    props: dict[str, Any] = {}
    for f in fields:
        if not f.get("editable", True):
            continue
        kind = f["kind"]
        if kind == "choice":
            one: dict[str, Any] = {"enum": list(f["choices"])}
        else:
            one = dict(_PRIMITIVE.get(kind, {}))
            if kind in ("int", "float"):
                one.update({k: f[src] for k, src in (("minimum", "min"), ("maximum", "max")) if isinstance(f.get(src), (int, float))})
        if f.get("help"):
            one["description"] = f["help"]
        props[f["name"]] = {"anyOf": [one, {"type": "null"}]} if f.get("optional") else one
    return {"type": "object", "properties": props, "additionalProperties": False, "minProperties": 1}


def goal_schema(goal_cls: type) -> dict[str, Any]:
    whole = message_schema(goal_cls)
    return {"anyOf": [GOAL_POINT, whole]} if goal_field(goal_cls) is not None else whole


def envelope(key: str, schema: dict[str, Any]) -> dict[str, Any]:
    return {"type": "object", "properties": {key: schema}, "required": [key], "additionalProperties": False}


# ---------------------------------------------------------------------- checking
_JSON_TYPES: dict[str, Any] = {
    "object": lambda v: isinstance(v, dict), "array": lambda v: isinstance(v, list), "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool), "null": lambda v: v is None,
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool) or isinstance(v, float) and math.isfinite(v) and v.is_integer(),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
}


def check(schema: dict[str, Any], value: Any, where: str = "body") -> None:
    """Raise :class:`RequestInvalid` naming the first part of ``value`` that ``schema`` refuses."""
    if "anyOf" in schema:
        errors = []
        for option in schema["anyOf"]:
            try:
                check(option, value, where)
                return
            except RequestInvalid as exc:
                errors.append(exc)
        deepest = max(errors, key=lambda e: e.field.count(".") + e.field.count("["))
        raise deepest
    want = schema.get("type")
    if want is not None and not _JSON_TYPES[want](value):
        if want == "number" and isinstance(value, float):
            raise RequestInvalid(where, f"expected a finite number, got {value!r}")
        raise RequestInvalid(where, f"expected {'an' if want[0] in 'aeio' else 'a'} {want}, got {_json_type(value)} {_short(value)}")
    if want in ("integer", "number"):
        if "minimum" in schema and value < schema["minimum"]:
            raise RequestInvalid(where, f"must be >= {schema['minimum']}, got {value!r}")
        if "maximum" in schema and value > schema["maximum"]:
            raise RequestInvalid(where, f"must be <= {schema['maximum']}, got {value!r}")
    if want == "string" and "maxLength" in schema and len(value) > schema["maxLength"]:
        raise RequestInvalid(where, f"at most {schema['maxLength']} characters, got {len(value)}")
    if want == "array":
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            raise RequestInvalid(where, f"at most {schema['maxItems']} items, got {len(value)}")
        for i, item in enumerate(value):
            check(schema.get("items", {}), item, f"{where}[{i}]")
    if want == "object":
        props = schema.get("properties", {})
        if len(value) < schema.get("minProperties", 0):
            raise RequestInvalid(where, f"give at least {schema['minProperties']} of: {', '.join(props) or 'none'}")
        for name in schema.get("required", []):
            if name not in value:
                raise RequestInvalid(f"{where}.{name}", "required")
        if schema.get("additionalProperties") is False:
            extra = sorted(k for k in value if k not in props)
            if extra:
                raise RequestInvalid(f"{where}.{extra[0]}", f"unknown field; fields are {', '.join(props) or 'none'}")
        for name, sub in props.items():
            if name in value:
                check(sub, value[name], f"{where}.{name}")
    if "enum" in schema and value not in schema["enum"]:
        raise RequestInvalid(where, f"must be one of {schema['enum']}, got {_short(value)}")


def _json_type(value: Any) -> str:
    for name in ("null", "boolean", "integer", "number", "string", "array", "object"):
        if _JSON_TYPES[name](value):
            return name
    return type(value).__name__


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------------- the document
ERROR = {"type": "object", "properties": {"ok": {"type": "boolean"}, "error": {"type": "string"}, "field": {"type": "string"}}}


def _responses(ok: dict[str, Any], *codes: int) -> dict[str, Any]:
    out: dict[str, Any] = {"200": {"description": "done", "content": {"application/json": {"schema": ok}}}}
    words = {202: "accepted", 400: "malformed body", 401: "no or wrong credential", 403: "role or origin refused", 404: "no such input, component or action",
             409: "nothing to cancel, or not allowed in this state", 415: "wrong content type", 422: "a field does not fit (named in 'field')", 429: "too many failed sign-ins",
             503: "the component or supervisor is not reachable", 504: "the call timed out"}
    for code in codes:
        out[str(code)] = {"description": words[code], "content": {"application/json": {"schema": ERROR}}}
    return out


def document(title: str, inputs: dict[str, str], actions: dict[str, Any], services: dict[str, Any], outputs: list[dict[str, Any]],
             settings: dict[str, list[dict[str, Any]]] | None = None, system_actions: tuple[str, ...] = ()) -> dict[str, Any]:
    """The OpenAPI 3.1 document of this UI's API (paths per input, action and service; the
    components' settings (``settings``: name -> settings.describe_config) and lifecycle actions)."""
    paths: dict[str, Any] = {}
    common = (400, 401, 403, 415, 422, 429)
    ok = {"type": "object", "properties": {"ok": {"type": "boolean"}}}
    for topic, type_name in inputs.items():
        name = topic.lstrip("/")
        kind = input_kind(type_name)
        if kind in RAW_TYPES:
            body = {"required": True, "content": {t: {"schema": {"type": "string", "format": "binary"}} for t in RAW_TYPES[kind]}}
        else:
            body = {"required": True, "content": {"application/json": {"schema": envelope("value", input_schema(type_name))}}}
        paths[f"/api/v1/inputs/{name}"] = {"post": {
            "summary": f"publish one {type_name} on {topic}", "operationId": f"publish_{_op(name)}", "tags": ["inputs"],
            "requestBody": body, "responses": _responses(ok, *common)}}
    for name, a in actions.items():
        key = name.strip("/")
        state = {"type": "object", "properties": {"goal_id": {"type": "string"}, "state": {"type": "string"}}}
        paths[f"/api/v1/actions/{key}/goals"] = {"post": {
            "summary": f"send a {a.goal_type.__name__} goal to {key} (feedback: GET the goal, or the websocket)",
            "operationId": f"goal_{_op(key)}", "tags": ["actions"],
            "requestBody": {"required": True, "content": {"application/json": {"schema": envelope("goal", goal_schema(a.goal_type))}}},
            "responses": {**_responses(state, *common), "202": {"description": "goal sent", "content": {"application/json": {"schema": state}}}}}}
        gid = [{"name": "goal_id", "in": "path", "required": True, "schema": {"type": "string", "pattern": "^[0-9a-f]{32}$"}}]
        paths[f"/api/v1/actions/{key}/goals/{{goal_id}}"] = {"get": {
            "summary": f"state, feedback and result of a goal of {key}", "operationId": f"goal_state_{_op(key)}", "tags": ["actions"],
            "parameters": gid, "responses": _responses(state, 401, 403, 404, 429)}}
        paths[f"/api/v1/actions/{key}/goals/{{goal_id}}/cancel"] = {"post": {
            "summary": f"cancel a running goal of {key}", "operationId": f"cancel_{_op(key)}", "tags": ["actions"], "parameters": gid,
            "requestBody": {"required": False, "content": {"application/json": {"schema": {"type": "object"}}}},
            "responses": {**_responses(ok, 401, 403, 404, 409, 415, 429), "202": {"description": "cancel requested"}}}}
    for name, s in services.items():
        key = name.strip("/")
        paths[f"/api/v1/services/{key}"] = {"post": {
            "summary": f"call the service {key} ({s.request_type.__name__} -> {s.response_type.__name__}) and wait for its response",
            "operationId": f"call_{_op(key)}", "tags": ["services"],
            "requestBody": {"required": True, "content": {"application/json": {"schema": envelope("request", message_schema(s.request_type))}}},
            "responses": _responses({"type": "object", "properties": {"ok": {"type": "boolean"}, "response": {}}}, *common, 503, 504)}}
    out_names = [o["topic"].lstrip("/") for o in outputs]
    sample = {"type": "object", "properties": {"topic": {"type": "string"}, "seq": {"type": "integer"}, "stamp": {"type": "number"}, "value": {}}}
    for name in out_names:
        paths[f"/api/v1/outputs/{name}/latest"] = {"get": {
            "summary": f"the latest message on /{name} (as JSON; long arrays cut)", "operationId": f"latest_{_op(name)}", "tags": ["outputs"],
            "responses": _responses(sample, 401, 403, 429)}}
    listing = {"type": "object"}
    settings = settings or {}
    names = ", ".join(sorted(settings)) or "none"
    # One path with the component as a parameter (not one path per component): a schema-based
    # generator exploring the document must not stop the robot's components or retune them at
    # random. Each component's own schema is in components.schemas and in GET /api/v1/settings.
    component = [{"name": "component", "in": "path", "required": True, "schema": {"type": "string"},
                  "description": f"a component of the recipe: {names}"}]
    schemas = {f"settings_{_op(n)}": settings_schema(fields) for n, fields in sorted(settings.items())}
    paths["/api/v1/settings"] = {"get": {
        "summary": "every component's parameters: the form (kind, range, choices), the current values and the schema of a change",
        "operationId": "settings", "tags": ["settings"], "responses": _responses(listing, 401, 429)}}
    paths["/api/v1/settings/{component}"] = {"post": {
        "summary": "change parameters of a running component (operators); validated by the component, all or nothing",
        "description": "The body's 'values' follows the component's schema, components.schemas.settings_<component> "
                       "(also in GET /api/v1/settings). A wrong type, an unknown or read-only parameter: 422 naming it; "
                       "an unknown component: 404.",
        "operationId": "change_settings", "tags": ["settings"], "parameters": component,
        "requestBody": {"required": True, "content": {"application/json": {"schema": envelope(
            "values", {"type": "object", "minProperties": 1, "description": "parameter name -> new value"})}}},
        "responses": _responses({"type": "object", "properties": {"ok": {"type": "boolean"}, "values": {"type": "object"}}},
                                400, 401, 403, 404, 415, 422, 429, 503)}}
    for act in system_actions:
        paths[f"/api/v1/components/{{component}}/{act}"] = {"post": {
            "summary": {"start": "activate a component (the lifecycle's activate; its process stays)",
                        "stop": "deactivate a component (the lifecycle's deactivate; its process stays, its topics stay open)",
                        "restart": "restart a component's process (its supervisor starts a fresh one; counts against the restart intensity)"}
            .get(act, act) + " (operators)",
            "operationId": f"component_{act}", "tags": ["system"], "parameters": component,
            "requestBody": {"required": False, "content": {"application/json": {"schema": {"type": "object"}}}},
            "responses": _responses({"type": "object", "properties": {"ok": {"type": "boolean"}, "detail": {"type": "string"}}},
                                    401, 403, 404, 409, 415, 429, 503)}}
    paths.update({
        "/api/v1/session": {"get": {"summary": "who this credential is (role, device, expiry) and the session's CSRF token",
                                    "operationId": "session", "tags": ["meta"], "responses": _responses(listing, 401, 429)}},
        "/api/v1/inputs": {"get": {"summary": "inputs, actions and services with their JSON Schemas", "operationId": "list_inputs",
                                   "tags": ["inputs"], "responses": _responses(listing, 401, 429)}},
        "/api/v1/outputs": {"get": {"summary": "the outputs this UI shows", "operationId": "list_outputs", "tags": ["outputs"],
                                    "responses": _responses(listing, 401, 429)}},
        "/api/v1/system": {"get": {"summary": "the supervision tree: groups, components, pids, states, health, restarts",
                                   "operationId": "system", "tags": ["system"], "responses": _responses(listing, 401, 429, 503)}},
        "/api/v1/graph": {"get": {"summary": "the system graph: components, topics, events and actions", "operationId": "graph",
                                  "tags": ["system"], "responses": _responses(listing, 401, 429)}},
        "/api/v1/logs": {"get": {"summary": "the supervisor's events and the last lines of the run's log", "operationId": "logs", "tags": ["system"],
                                 "parameters": [{"name": "since", "in": "query", "schema": {"type": "number"}, "description": "events after this UNIX time"},
                                                {"name": "lines", "in": "query", "schema": {"type": "integer", "minimum": 0, "maximum": 5000}}],
                                 "responses": _responses(listing, 400, 401, 429)}},
    })
    return {
        "openapi": "3.1.0",
        "info": {"title": f"{title} API", "version": "1",
                 "description": "The EMOS web UI's API (docs/ui.md). Sign in with 'Authorization: Bearer <token>' (the run's token or a "
                                "device token from POST /api/pair). Viewers may GET; operators may also POST. The websocket "
                                "/api/v1/ws streams outputs at a rate the client chooses: send {\"op\": \"subscribe\", \"topic\": T, "
                                "\"rate\": HZ}; it also takes publish, goal, cancel and call ops (operators)."},
        "servers": [{"url": "/"}],
        "components": {"securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}}, "schemas": schemas},
        "security": [{"bearer": []}],
        "paths": paths,
    }


def _op(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)
