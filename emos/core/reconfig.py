"""Live reconfiguration and action services of every component (on its control socket).

=============================  ==============================================================
``change_topic``               replace an input (``direction`` 0) or output (1) topic: the
                               component goes down to Unconfigured, swaps it, and comes back
                               to the state it was in
``update_config_parameter``    one parameter; ``update_config_parameters``: several (all or none)
``configure_from_file``        a YAML, TOML or JSON file (its ``/**`` and own sections)
``execute_method``             call a public method of the component (arguments and result in
                               the wire format of :mod:`emos.core.control`); actions,
                               fallbacks, the CLI and other runs all call methods this way
``run_step``                   one step of a component whose trigger is an Event
=============================  ==============================================================

The op names, the socket path, the wire format and the clients live in :mod:`emos.core.control`.

Every parameter change is validated by the component's attrs config: a bad value is refused with
the validator's message and the old value stays. ``keep_alive=False`` deactivates the component
for the change and reactivates it after. All handlers run on the component's event loop, so they
are ordered with its steps, never concurrent with one.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from emos.core import control as C
from emos.core import lifecycle as L
from emos.core.control import ControlClient, decode_value, encode_result, public_method, request_lifecycle
from emos.io.topic import Topic, normalize_topic_name

if TYPE_CHECKING:  # for annotations only: the node imports this module
    from emos.core.node import Node

__all__ = ["reconfig_ops", "request_lifecycle", "ComponentServices"]
T = TypeVar("T")


async def _cycle(node: Node, down_to: L.LifecycleState, change: Callable[[], T]) -> T:
    """Bring the node down to ``down_to`` (if it is above), apply ``change``, bring it back."""
    order = [L.LifecycleState.UNCONFIGURED, L.LifecycleState.INACTIVE, L.LifecycleState.ACTIVE]
    was = node.state
    if was not in order:
        raise RuntimeError(f"component {node.name!r} is {was.value}; it cannot be reconfigured")
    if order.index(was) > order.index(down_to):
        for t in L.path_to(was, down_to):
            await node.transition(t)
    try:
        return change()
    finally:
        if node.state != was:
            for t in L.path_to(node.state, was):
                await node.transition(t)


def reconfig_ops(node: Node) -> dict[str, Callable[..., Any]]:
    comp = node.component

    async def update_params(values: dict[str, Any], keep_alive: bool) -> dict[str, Any]:
        if not isinstance(values, dict) or not values:
            raise ValueError("expects 'values': a non-empty map of parameter names to values")

        def apply() -> dict[str, Any]:
            comp.config.update(**values)  # all validated first; nothing changes on an error
            node.on_config_changed()
            comp.get_logger().info("[%s] parameters set: %s", comp.component_name, ", ".join(f"{k}={v!r}" for k, v in values.items()))
            config: dict[str, Any] = comp.config.asdict()
            return config

        if keep_alive:
            return apply()
        return await _cycle(node, L.LifecycleState.INACTIVE, apply)

    async def update_config_parameter(req: dict[str, Any], stream: Any) -> dict[str, Any]:
        name = req.get("name")
        if not isinstance(name, str):
            raise ValueError("update_config_parameter expects 'name' (str) and 'value'")
        return await update_params({name: req.get("value")}, bool(req.get("keep_alive", True)))

    async def update_config_parameters(req: dict[str, Any], stream: Any) -> dict[str, Any]:
        values = req.get("values")
        if values is None and "names" in req:
            names, vals = list(req.get("names") or []), list(req.get("values_list") or req.get("new_values") or [])
            if len(names) != len(vals):
                raise ValueError(f"update_config_parameters: {len(names)} names but {len(vals)} values")
            values = dict(zip(names, vals))
        return await update_params(values or {}, bool(req.get("keep_alive", True)))

    async def configure_from_file(req: dict[str, Any], stream: Any) -> dict[str, Any]:
        path = str(req["path"])

        def apply() -> dict[str, Any]:
            comp.configure(path)
            node.on_config_changed()
            config: dict[str, Any] = comp.config.asdict()
            return config

        if bool(req.get("keep_alive", True)):
            return apply()
        return await _cycle(node, L.LifecycleState.INACTIVE, apply)

    async def change_topic(req: dict[str, Any], stream: Any) -> dict[str, Any]:
        direction = req.get("direction", 0)
        direction = {"input": 0, "output": 1}.get(direction, direction) if isinstance(direction, str) else direction
        if direction not in (0, 1):
            raise ValueError(f"change_topic: direction must be 0 (input) or 1 (output), got {req.get('direction')!r}")
        attr = "in_topics" if direction == 0 else "out_topics"
        old_name = normalize_topic_name(str(req.get("old_name", "")))
        topics: list[Topic] = getattr(comp, attr)
        old = next((t for t in topics if t.name == old_name), None)
        if old is None:
            raise KeyError(f"component {node.name!r} has no {'input' if direction == 0 else 'output'} {old_name!r}; it has {sorted(t.name for t in topics)}")
        new = Topic(name=str(req["new_name"]), msg_type=req.get("new_msg_type") or old.msg_type, qos_profile=old.qos_profile, data_timeout=old.data_timeout)

        def swap() -> dict[str, Any]:
            topics[topics.index(old)] = new
            if old in comp._trigger:
                comp._trigger[comp._trigger.index(old)] = new
            return {"old": old.name, "new": new.name, "msg_type": new.type_name}

        return await _cycle(node, L.LifecycleState.UNCONFIGURED, swap)

    async def execute_method(req: dict[str, Any], stream: Any) -> Any:
        method = public_method(comp, req.get("method", ""), node.name)
        args, kwargs = req.get("args") or [], req.get("kwargs") or {}
        if not isinstance(args, list) or not isinstance(kwargs, dict):
            raise TypeError(f"execute_method {node.name}.{req.get('method')}: 'args' must be a list and 'kwargs' a map, "
                            f"got {type(args).__name__} and {type(kwargs).__name__}")
        try:
            return encode_result(method(*decode_value(args), **decode_value(kwargs)))
        finally:
            node.publish_status()  # what the method did to the health is seen at once (fallbacks wait for it)

    async def run_step(req: dict[str, Any], stream: Any) -> bool:
        if node.state != L.LifecycleState.ACTIVE:
            raise RuntimeError(f"component {node.name!r} is {node.state.value}, not active: step not run")
        node._run_step()
        return True

    return {
        C.UPDATE_PARAMETER: update_config_parameter, C.UPDATE_PARAMETERS: update_config_parameters,
        C.CONFIGURE_FROM_FILE: configure_from_file, C.CHANGE_TOPIC: change_topic,
        C.EXECUTE_METHOD: execute_method, C.RUN_STEP: run_step,
    }


class ComponentServices:
    """The live-reconfiguration services of one running component, from Python.

        ComponentServices("controller").update_parameter("loop_rate", 5.0)

    Works from any process of the run (a recipe function, a component, a test given ``ctx``);
    a refused change raises :class:`~emos.core.rpc.RpcError` with the validator's message.
    """

    def __init__(self, component_name: str, ctx: Any = None, timeout: float = 15.0):
        self.component_name = component_name
        self._client = ControlClient(component_name, ctx, timeout=timeout)
        self.path = self._client.path
        self.timeout = timeout

    def _call(self, op: str, **payload: Any) -> dict[str, Any]:
        """One of the reconfiguration operations, which all answer with a map."""
        self._client.timeout = self.timeout
        answer: dict[str, Any] = self._client.call(op, **payload)
        return answer

    def change_topic(self, direction: int | str, old_name: str, new_name: str, new_msg_type: str | None = None) -> dict[str, Any]:
        return self._call(C.CHANGE_TOPIC, direction=direction, old_name=old_name, new_name=new_name, new_msg_type=new_msg_type)

    def update_parameter(self, name: str, value: Any, keep_alive: bool = True) -> dict[str, Any]:
        return self._call(C.UPDATE_PARAMETER, name=name, value=value, keep_alive=keep_alive)

    def update_parameters(self, values: dict[str, Any], keep_alive: bool = True) -> dict[str, Any]:
        return self._call(C.UPDATE_PARAMETERS, values=values, keep_alive=keep_alive)

    def configure_from_file(self, path: str, keep_alive: bool = True) -> dict[str, Any]:
        return self._call(C.CONFIGURE_FROM_FILE, path=path, keep_alive=keep_alive)

    def execute_method(self, method: str, *args: Any, **kwargs: Any) -> Any:
        self._client.timeout = self.timeout
        return self._client.execute_method(method, *args, **kwargs)

    def info(self) -> dict[str, Any]:
        return self._call(C.INFO)
