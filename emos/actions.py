"""Predefined actions, keyword-only as in the spec: ``restart(component=planner)``.

Component-level actions act on one component: lifecycle (``start``, ``stop``, ``restart``: through
the supervisor, so ``restart`` counts against its restart intensity), parameters
(``reconfigure``, ``update_parameter``, ``update_parameters``: validated by the component's attrs
config inside its process; a bad value is refused and the old one kept) and its main service or
action server. System-level actions run where the action runs (the Monitor for events, the
supervisor for fallbacks): ``log``, ``publish_message``, and calls to any service or action
server by name. ``trigger_*`` builds the request from the event's message where its fields
match the request's, and sends the default request otherwise.
"""
from __future__ import annotations

import logging
import os
from typing import Any

import attrs

from emos.config.base import BaseComponentConfig
from emos.core import control as C
from emos.core.component import BaseComponent
from emos.events.action import Action, Literal
from emos.events.runner import ActionRuntime
from emos.io.topic import Topic
from emos.msgs.registry import resolve

__all__ = [
    "start", "stop", "restart", "reconfigure", "update_parameter", "update_parameters",
    "send_component_service_request", "trigger_component_service", "send_component_action_server_goal",
    "trigger_component_action_server", "log", "publish_message", "send_srv_request", "trigger_service",
    "send_action_goal", "trigger_action_server", "Action", "LogInfo", "ComponentActions",
]


def _component(value: Any, action: str) -> BaseComponent:
    if not isinstance(value, BaseComponent):
        raise TypeError(f"{action}: component must be a BaseComponent, got {type(value).__name__} {value!r}")
    return value


# ============================================================================ lifecycle
def _lifecycle(op: str, component: Any, wait_time: float = 0.0) -> Action:
    comp = _component(component, op)
    if isinstance(wait_time, bool) or not isinstance(wait_time, (int, float)) or wait_time < 0:
        raise ValueError(f"{op}: wait_time must be a number of seconds >= 0, got {wait_time!r}")
    action = Action(getattr(BaseComponent, op).__get__(comp), kwargs={"wait_time": float(wait_time)} if wait_time else None)
    return action


def start(*, component: BaseComponent) -> Action:
    """Activate the component (Inactive -> Active)."""
    return _lifecycle("start", component)


def stop(*, component: BaseComponent) -> Action:
    """Deactivate the component (Active -> Inactive); it keeps its process and heartbeat."""
    return _lifecycle("stop", component)


def restart(*, component: BaseComponent, wait_time: float = 0.0) -> Action:
    """Restart the component through the supervisor (a fresh incarnation, counted against the
    restart intensity), waiting ``wait_time`` seconds between stop and start."""
    return _lifecycle("restart", component, wait_time)


# ============================================================================ parameters
async def _call(rt: ActionRuntime, component: str, op: str, **payload: Any) -> Any:
    return await rt.call_component(component, op, rt.timeout, **payload)


async def _reconfigure(rt: ActionRuntime, *, component: str, new_config: Any, keep_alive: bool, **_: Any) -> Any:
    if isinstance(new_config, str):
        return await _call(rt, component, C.CONFIGURE_FROM_FILE, path=new_config, keep_alive=keep_alive)
    return await _call(rt, component, C.UPDATE_PARAMETERS, values=new_config, keep_alive=keep_alive)


def reconfigure(*, component: BaseComponent, new_config: Any = None, keep_alive: bool = True, file: str | None = None) -> Action:
    """Apply a whole config object or a config file (YAML, TOML, JSON) to a running component."""
    comp = _component(component, "reconfigure")
    if (new_config is None) == (file is None):
        raise ValueError("reconfigure: give exactly one of new_config (a config object or a file path) and file")
    source = file if file is not None else new_config
    if isinstance(source, str):
        if not os.path.isfile(source):
            raise FileNotFoundError(f"reconfigure({comp.component_name}): config file {source!r} does not exist")
        payload: Any = os.path.abspath(source)
    elif isinstance(source, BaseComponentConfig):
        if not isinstance(source, type(comp.config)):
            raise TypeError(f"reconfigure({comp.component_name}): new_config must be a {type(comp.config).__name__}, got {type(source).__name__}")
        payload = source.asdict()
    else:
        raise TypeError(f"reconfigure({comp.component_name}): new_config must be a config object or a file path, got {type(source).__name__}")
    return Action._predefined("reconfigure", _reconfigure, comp.component_name, component=comp.component_name, new_config=payload, keep_alive=bool(keep_alive))


def _check_params(comp: BaseComponent, names: list[str], action: str) -> None:
    known = {f.name for f in attrs.fields(type(comp.config))}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise AttributeError(f"{action}({comp.component_name}): {type(comp.config).__name__} has no parameter {', '.join(unknown)}; parameters are {', '.join(sorted(known))}")


async def _update(rt: ActionRuntime, *, component: str, values: dict[str, Any], keep_alive: bool, **_: Any) -> Any:
    return await _call(rt, component, C.UPDATE_PARAMETERS, values=values, keep_alive=keep_alive)


def update_parameter(*, component: BaseComponent, param_name: str, new_value: Any, keep_alive: bool = True) -> Action:
    """Set one config parameter of a running component (validated there; refused if invalid)."""
    comp = _component(component, "update_parameter")
    _check_params(comp, [param_name], "update_parameter")
    return Action._predefined("update_parameter", _update, comp.component_name, component=comp.component_name, values={param_name: new_value}, keep_alive=bool(keep_alive))


def update_parameters(*, component: BaseComponent, params_names: list[str], new_values: list[Any], keep_alive: bool = True) -> Action:
    """Set several config parameters at once: all are applied or none."""
    comp = _component(component, "update_parameters")
    names, values = list(params_names), list(new_values)
    if len(names) != len(values):
        raise ValueError(f"update_parameters({comp.component_name}): {len(names)} names but {len(values)} values")
    _check_params(comp, names, "update_parameters")
    return Action._predefined("update_parameters", _update, comp.component_name, component=comp.component_name, values=dict(zip(names, values)), keep_alive=bool(keep_alive))


# ============================================================================ services and action servers
def request_from_event(request_type: type, trigger_msg: Any) -> Any:
    """The request built from the event's message where field names match; the default otherwise."""
    if trigger_msg is None or not attrs.has(type(trigger_msg)):
        return request_type()
    src = {f.name for f in attrs.fields(type(trigger_msg))}
    values = {}
    for f in attrs.fields(request_type):
        if f.name in src:
            values[f.name] = getattr(trigger_msg, f.name)
    if not values:
        return request_type()
    try:
        return request_type(**values)
    except Exception:
        return request_type()


async def _service(rt: ActionRuntime, *, srv_name: str, srv_type: tuple[type, type], request: Any, from_event: bool, trigger_msg: Any = None,
                   component: str | None = None, **_: Any) -> Any:
    req_t, resp_t = srv_type
    req = request_from_event(req_t, trigger_msg) if from_event else request
    response = await rt.call_service(srv_name, req, resp_t, component)
    rt.log.info("service %s answered %r", srv_name, response)
    return response


async def _goal(rt: ActionRuntime, *, server_name: str, action_type: tuple[type, type, type], goal: Any, from_event: bool, trigger_msg: Any = None,
                component: str | None = None, **_: Any) -> Any:
    msg = request_from_event(action_type[0], trigger_msg) if from_event else goal
    # A goal may run for minutes (follow a person): send it and do not hold the caller.
    return await rt.send_goal(server_name, action_type, msg, component)


def _types(value: Any, n: int, what: str) -> tuple[Any, ...]:
    """(request, response) or (goal, feedback, result) from a tuple of types/names or an object
    with ``main_srv_type``-like attributes (Request/Response, Goal/Feedback/Result)."""
    if isinstance(value, (tuple, list)) and len(value) == n:
        return tuple(resolve(v) for v in value)
    attrs_names = ("Request", "Response") if n == 2 else ("Goal", "Feedback", "Result")
    if all(hasattr(value, a) for a in attrs_names):
        return tuple(resolve(getattr(value, a)) for a in attrs_names)
    raise TypeError(f"{what} must be a tuple of {n} message types (or names), got {value!r}")


def send_component_service_request(*, component: BaseComponent, srv_request_msg: Any) -> Action:
    comp = _component(component, "send_component_service_request")
    if comp.main_srv_type is None:
        raise ValueError(f"send_component_service_request: {comp.component_name} ({type(comp).__name__}) has no main service")
    req_t, resp_t = (resolve(t) for t in comp.main_srv_type)
    if not isinstance(srv_request_msg, req_t):
        raise TypeError(f"send_component_service_request({comp.component_name}): srv_request_msg must be a {req_t.__name__}, got {type(srv_request_msg).__name__}")
    return Action._predefined("send_component_service_request", _service, comp.component_name, component=comp.component_name, srv_name=comp.main_srv_name, srv_type=(req_t, resp_t), request=srv_request_msg, from_event=False)


def trigger_component_service(*, component: BaseComponent) -> Action:
    comp = _component(component, "trigger_component_service")
    if comp.main_srv_type is None:
        raise ValueError(f"trigger_component_service: {comp.component_name} ({type(comp).__name__}) has no main service")
    return Action._predefined("trigger_component_service", _service, comp.component_name, component=comp.component_name, srv_name=comp.main_srv_name, srv_type=tuple(resolve(t) for t in comp.main_srv_type), request=None, from_event=True)


def send_component_action_server_goal(*, component: BaseComponent, request_msg: Any) -> Action:
    """Send ``request_msg`` to the component's action server for that goal type: its main one,
    or another it offers (the Controller's ``track_vision_target`` for a ``TrackVisionTarget`` goal)."""
    comp = _component(component, "send_component_action_server_goal")
    servers = {name: tuple(resolve(t) for t in types) for name, types in comp.action_servers().items()}
    if not servers:
        raise ValueError(f"send_component_action_server_goal: {comp.component_name} ({type(comp).__name__}) has no action server")
    for name, types in servers.items():
        if isinstance(request_msg, types[0]):
            return Action._predefined("send_component_action_server_goal", _goal, comp.component_name, component=comp.component_name, server_name=name, action_type=types, goal=request_msg, from_event=False)
    accepted = ", ".join(f"{types[0].__name__} ({name})" for name, types in servers.items())
    raise TypeError(f"send_component_action_server_goal({comp.component_name}): request_msg must be one of {accepted}, got {type(request_msg).__name__}")


def trigger_component_action_server(*, component: BaseComponent) -> Action:
    comp = _component(component, "trigger_component_action_server")
    if comp.main_action_type is None:
        raise ValueError(f"trigger_component_action_server: {comp.component_name} ({type(comp).__name__}) has no main action server")
    return Action._predefined("trigger_component_action_server", _goal, comp.component_name, component=comp.component_name, server_name=comp.main_action_name, action_type=tuple(resolve(t) for t in comp.main_action_type), goal=None, from_event=True)


def send_srv_request(*, srv_name: str, srv_type: Any, srv_request_msg: Any) -> Action:
    types = _types(srv_type, 2, "send_srv_request: srv_type")
    if not isinstance(srv_request_msg, types[0]):
        raise TypeError(f"send_srv_request({srv_name}): srv_request_msg must be a {types[0].__name__}, got {type(srv_request_msg).__name__}")
    return Action._predefined("send_srv_request", _service, srv_name=_name(srv_name, "send_srv_request"), srv_type=types, request=srv_request_msg, from_event=False)


def trigger_service(*, srv_name: str, srv_type: Any) -> Action:
    return Action._predefined("trigger_service", _service, srv_name=_name(srv_name, "trigger_service"), srv_type=_types(srv_type, 2, "trigger_service: srv_type"), request=None, from_event=True)


def send_action_goal(*, server_name: str, server_type: Any, request_msg: Any) -> Action:
    types = _types(server_type, 3, "send_action_goal: server_type")
    if not isinstance(request_msg, types[0]):
        raise TypeError(f"send_action_goal({server_name}): request_msg must be a {types[0].__name__}, got {type(request_msg).__name__}")
    return Action._predefined("send_action_goal", _goal, server_name=_name(server_name, "send_action_goal"), action_type=types, goal=request_msg, from_event=False)


def trigger_action_server(*, server_name: str, server_type: Any) -> Action:
    return Action._predefined("trigger_action_server", _goal, server_name=_name(server_name, "trigger_action_server"), action_type=_types(server_type, 3, "trigger_action_server: server_type"), goal=None, from_event=True)


def _name(value: Any, action: str) -> str:
    if not isinstance(value, str) or not value:
        raise TypeError(f"{action}: the name must be a non-empty str, got {value!r}")
    return value


# ============================================================================ system
async def _log(rt: ActionRuntime, *, msg: str, logger_name: str | None, **_: Any) -> None:
    logging.getLogger(logger_name or "emos.actions").info("%s", msg)


def log(*, msg: str, logger_name: str | None = None) -> Action:
    """Log ``msg`` (at INFO) to ``logger_name`` or ``emos.actions``."""
    if not isinstance(msg, str):
        raise TypeError(f"log: msg must be a str, got {type(msg).__name__}")
    return Action._predefined("log", _log, msg=msg, logger_name=logger_name)


async def _publish(rt: ActionRuntime, *, topic: Topic, msg: Any, publish_rate: float | None, publish_period: float | None, key: str, **_: Any) -> None:
    if publish_rate is None:
        rt.publish(topic, msg)
        return
    rt.periodic(key, 1.0 / publish_rate, publish_period, lambda: rt.publish(topic, msg))


def publish_message(*, topic: Topic, msg: Any, publish_rate: float | None = None, publish_period: float | None = None) -> Action:
    """Publish ``msg`` on ``topic`` once, or ``publish_rate`` times a second for ``publish_period``
    seconds (None: until the system stops). A new firing restarts the periodic publication."""
    if not isinstance(topic, Topic):
        raise TypeError(f"publish_message: topic must be a Topic, got {type(topic).__name__}")
    if not isinstance(msg, topic.msg_type):
        raise TypeError(f"publish_message({topic.name}): msg must be a {topic.type_name}, got {type(msg).__name__}")
    for name, value in (("publish_rate", publish_rate), ("publish_period", publish_period)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0):
            raise ValueError(f"publish_message({topic.name}): {name} must be a positive number or None, got {value!r}")
    if publish_period is not None and publish_rate is None:
        raise ValueError(f"publish_message({topic.name}): publish_period needs publish_rate")
    action = Action._predefined("publish_message", _publish, topic=Literal(topic), msg=msg, publish_rate=publish_rate, publish_period=publish_period, key="")
    action.kwargs["key"] = f"publish:{topic.name}:{id(action)}"
    return action


# ============================================================================ Kompass spellings
def LogInfo(*, msg: str, logger_name: str | None = None) -> Action:  # noqa: N802 (the seed's name)
    """``log`` under the name Kompass recipes use."""
    return log(msg=msg, logger_name=logger_name)


class ComponentActions:
    """The Kompass spellings of the service and action-server actions."""

    @staticmethod
    def send_srv_request(*, srv_name: str, srv_type: Any, srv_request_msg: Any) -> Action:
        return send_srv_request(srv_name=srv_name, srv_type=srv_type, srv_request_msg=srv_request_msg)

    @staticmethod
    def send_action_goal(*, action_name: str, action_type: Any, action_request_msg: Any) -> Action:
        """The goal can be replaced at fire time: ``.event_parser(fn, output_mapping="action_request_msg")``."""
        action = send_action_goal(server_name=action_name, server_type=action_type, request_msg=action_request_msg)
        action.kwargs["action_request_msg"] = action.kwargs["goal"]
        action.method = _goal_alias
        return action


async def _goal_alias(rt: ActionRuntime, *, action_request_msg: Any, goal: Any = None, **kwargs: Any) -> Any:
    return await _goal(rt, goal=action_request_msg, **kwargs)
