"""Cortex's tools: what the running system offers, as OpenAI-style tool specs, each with the
``emos.actions`` Action that carries it out (the machinery events and fallbacks use).

Discovery asks the run itself, as ``emos component list`` / ``emos action list`` /
``emos service list`` do: the supervisor's ``tree`` for the components, then each component's
``info`` answer (its type, topics, services and action servers, from
:func:`emos.core.services.describe_interfaces`). From that:

* every action server and service becomes a tool ``<component>__<name>`` whose parameters are
  the goal's (request's) fields as a JSON schema (:func:`message_schema`);
* a navigation Planner's ``plan_path`` also becomes ``navigate_to_point(x, y)`` and, when the
  recipe names places, ``navigate_to(place)``;
* a Vision component becomes ``<component>__snapshot()``: what it detects now (its latest
  Detections);
* a TextToSpeech component becomes ``<component>__say(text)``: the text on its input topic;
* and the recipe adds its own: component methods and functions (``Cortex.add_tool``).

The peer answers are untrusted: names are checked against the control plane's rules and the
types are only resolved among registered messages (never imported by name).
"""
from __future__ import annotations

import functools
import re
from collections.abc import Callable
from typing import Any

import attrs
import numpy as np

from emos.core.discovery import interfaces_of, printable
from emos.msgs import fields as F

from ..types import ToolSpec

__all__ = ["message_schema", "CortexTool", "tools_from_info", "tool_name", "SEPARATOR", "describe_detections", "method_action"]

SEPARATOR = "__"  # component__action: OpenAI tool names allow [a-zA-Z0-9_-] only
_UNSAFE = re.compile(r"[^A-Za-z0-9_-]")
_MAX_DEPTH = 4  # message nesting that is worth showing a model; deeper parts keep their defaults


def tool_name(*parts: str) -> str:
    """A tool name OpenAI and Ollama accept (letters, digits, _ and -; at most 64)."""
    return _UNSAFE.sub("_", SEPARATOR.join(p.strip("/").replace("/", "_") for p in parts if p))[:64]


def message_schema(cls: type, depth: int = 0, skip: tuple[str, ...] = ("header",)) -> dict:
    """A JSON schema (type object) of a message class's fields, from the field kinds the codec uses;
    headers and images (which a model cannot write) are left out."""
    props: dict[str, Any] = {}
    sample = cls()
    for field in attrs.fields(cls):
        if field.name in skip:
            continue
        kind = field.metadata.get("kind")
        default = getattr(sample, field.name)
        if kind == F.PRIMITIVE:
            props[field.name] = {"type": "boolean" if isinstance(default, bool) else "integer" if isinstance(default, int)
                                 else "number" if isinstance(default, float) else "string"}
        elif kind == F.STR_LIST:
            props[field.name] = {"type": "array", "items": {"type": "string"}}
        elif kind == F.ARRAY and isinstance(default, np.ndarray) and default.dtype.kind in "fiu":
            props[field.name] = {"type": "array", "items": {"type": "number"}}
        elif kind == F.MESSAGE and depth < _MAX_DEPTH:
            sub = field.metadata["cls"]()
            if getattr(sub, "__name__", "") in ("Image", "CompressedImage"):
                continue
            props[field.name] = message_schema(sub, depth + 1, ())
    return {"type": "object", "properties": props}


@attrs.frozen
class CortexTool:
    """A tool: its spec for the model and ``make(arguments) -> Action`` for the executor.
    ``component`` names the component whose health the step depends on (None: none)."""

    spec: ToolSpec
    make: Callable[[dict], Any]
    component: str | None = None
    kind: str = "function"
    waits: bool = False  # the Action returns the goal's result (an action server): judge it


def _goal_action(server: str, types: tuple[type, ...], build: Callable[[dict], Any]) -> Callable[[dict], Any]:
    from emos import actions as A

    return lambda args: A.send_action_goal(server_name=server, server_type=types, request_msg=build(args))


def _from_fields(cls: type) -> Callable[[dict], Any]:
    from emos.msgs import codec

    return lambda args: codec.from_builtin(cls, args)


def tools_from_info(info: dict, places: dict[str, tuple[float, float]] | None = None,
                    topic_of: Callable[[str, str], Any] | None = None) -> list[CortexTool]:
    """The tools one component's ``info`` answer offers (see the module doc). ``topic_of(name,
    type)`` gives the Topic object for publishing to an input (speech)."""

    component = printable(info.get("component", ""), 120)
    kind = printable(info.get("type", ""), 120)
    if not component:
        return []
    out: list[CortexTool] = []
    # Only what is served now, and whose types this process knows (a type it does not know
    # cannot be built: not offered).
    for action in interfaces_of(component, "action", info.get("actions")):
        types = action.registered_types() if action.serving else None
        if types is None:
            continue
        server = action.name
        short = server.split("/")[-1]
        out.append(CortexTool(ToolSpec(name=tool_name(component, short),
                                       description=f"Action {server} of {kind} {component!r}: send a {types[0].__name__} goal and wait for its result.",
                                       parameters=message_schema(types[0])),
                              _goal_action(server, types, _from_fields(types[0])), component, "action", waits=True))
        if kind == "Planner" and short == "plan_path":
            out += _navigation(server, types, component, places or {})
    for service in interfaces_of(component, "service", info.get("services")):
        types = service.registered_types() if service.serving else None
        if types is None:
            continue
        srv = service.name
        req_t = types[0]
        out.append(CortexTool(ToolSpec(name=tool_name(component, srv.split("/")[-1]),
                                       description=f"Service {srv} of {kind} {component!r}: send a {req_t.__name__} request.",
                                       parameters=message_schema(req_t)),
                              functools.partial(_service_action, srv, types),
                              component, "service", waits=True))
    if kind == "Vision" and topic_of is not None:
        outputs = info.get("outputs") or {}
        det = next((n for n, t in outputs.items() if isinstance(t, str) and t.split("/")[-1] in ("Detections", "Trackings")), None)
        if det is not None:
            topic = topic_of(det, outputs[det])
            out.append(CortexTool(ToolSpec(name=tool_name(component, "snapshot"),
                                           description=f"What the camera sees now: the objects {component!r} detects in the latest frame.",
                                           parameters={"type": "object", "properties": {}}),
                                  functools.partial(_snapshot_action, topic), component, "snapshot"))
    if kind == "TextToSpeech" and topic_of is not None:
        inputs = info.get("inputs") or {}
        text_in = next((n for n, t in inputs.items() if isinstance(t, str) and t.split("/")[-1] == "String"), None)
        if text_in is not None:
            topic = topic_of(text_in, inputs[text_in])
            out.append(CortexTool(ToolSpec(name=tool_name(component, "say"),
                                           description=f"Say a sentence aloud to the user through {component!r}.",
                                           parameters={"type": "object", "properties": {"text": {"type": "string", "minLength": 1}},
                                                       "required": ["text"]}),
                                  functools.partial(_say_action, topic), component, "speech"))
    if kind == "Memory":
        from ..memory.tools import MEMORY_TOOLS

        for spec in MEMORY_TOOLS.values():
            out.append(CortexTool(ToolSpec(name=tool_name(component, spec.name), description=spec.description,
                                           parameters=spec.parameters),
                                  functools.partial(method_action, component, spec.name), component, "component"))
    return out


def method_action(component: str, method: str, kwargs: dict) -> Any:
    """The Action an event would run for ``component.method(**kwargs)``, built from names (the
    component object lives in another process): it runs there through ``execute_method``."""
    from emos.events.action import Action

    def remote(**_: Any) -> None:  # never called here: a component action runs in its component
        raise RuntimeError(f"{component}.{method} runs inside {component}")

    action = Action(remote, kwargs=dict(kwargs))
    action.kind, action.component, action.method_name = "component", component, method
    return action


def codec_build(cls: type, args: dict) -> Any:
    from emos.msgs import codec

    return codec.from_builtin(cls, args)


def _navigation(server: str, types: tuple[type, ...], component: str, places: dict[str, tuple[float, float]]) -> list[CortexTool]:
    goal_t = types[0]

    def to_point(x: float, y: float) -> Any:
        return codec_build(goal_t, {"goal": {"position": {"x": float(x), "y": float(y), "z": 0.0}}})

    tools = [CortexTool(ToolSpec(name="navigate_to_point",
                                 description="Drive the robot to the map position (x, y) in metres and wait until it arrives.",
                                 parameters={"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}},
                                             "required": ["x", "y"]}),
                        _goal_action(server, types, lambda a: to_point(a["x"], a["y"])), component, "action", waits=True)]
    if places:
        names = sorted(places)
        tools.append(CortexTool(ToolSpec(name="navigate_to",
                                         description=f"Drive the robot to a named place and wait until it arrives. Places: {', '.join(names)}.",
                                         parameters={"type": "object", "properties": {"place": {"type": "string", "enum": names}},
                                                     "required": ["place"]}),
                                _goal_action(server, types, lambda a: to_point(*places[a["place"]])), component, "action", waits=True))
    return tools


def describe_detections(msg: Any) -> str:
    """A detections message in words, for the model."""
    if msg is None:
        return "no image has been seen yet"
    labels = list(getattr(msg, "labels", []) or [])
    if not labels:
        return "nothing detected"
    counts: dict[str, int] = {}
    for label in labels:
        counts[str(label)] = counts.get(str(label), 0) + 1
    return "detected: " + ", ".join(f"{n} {label}" if n > 1 else label for label, n in sorted(counts.items()))


def _service_action(srv: str, types: tuple[type, ...], args: dict) -> Any:
    from emos import actions as A

    return A.send_srv_request(srv_name=srv, srv_type=types, srv_request_msg=codec_build(types[0], args))


def _snapshot_action(topic: Any, args: dict) -> Any:
    from emos.events.action import Action

    def snapshot(detections: Any = None) -> str:
        return describe_detections(detections)

    return Action(snapshot, kwargs={"detections": topic})  # bound at run time: the latest message


def _say_action(topic: Any, args: dict) -> Any:
    from emos import actions as A
    from emos.msgs import String

    return A.publish_message(topic=topic, msg=String(data=args["text"]))
