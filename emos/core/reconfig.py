"""Live reconfiguration and action services of every component (on its control socket).

=============================  ==============================================================
``change_topic``               replace an input (``direction`` 0) or output (1) topic: the
                               component goes down to Unconfigured, swaps it, and comes back
                               to the state it was in
``update_config_parameter``    one parameter; ``update_config_parameters``: several (all or none)
``configure_from_file``        a YAML, TOML or JSON file (its ``/**`` and own sections)
``execute_method``             call a public method of the component
``run_action``                 a component-method action (arguments in the action wire format)
``run_step``                   one step of a component whose trigger is an Event
=============================  ==============================================================

Every parameter change is validated by the component's attrs config: a bad value is refused with
the validator's message and the old value stays. ``keep_alive=False`` deactivates the component
for the change and reactivates it after. All handlers run on the component's event loop, so they
are ordered with its steps, never concurrent with one.
"""
from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any, Callable

from emos.core import lifecycle as L
from emos.io.topic import Topic, normalize_topic_name

if TYPE_CHECKING:
    from emos.core.node import Node


def _jsonable(result: Any) -> Any:
    from emos.events.action import ActionError, encode_value

    try:
        return encode_value(result, "result")
    except ActionError:
        return repr(result)


async def _cycle(node: "Node", down_to: L.LifecycleState, change: Callable[[], Any]) -> Any:
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


def reconfig_ops(node: "Node") -> dict[str, Callable]:
    comp = node.component

    async def update_params(values: dict, keep_alive: bool) -> dict:
        if not isinstance(values, dict) or not values:
            raise ValueError("expects 'values': a non-empty map of parameter names to values")

        def apply() -> dict:
            comp.config.update(**values)  # all validated first; nothing changes on an error
            node.on_config_changed()
            comp.get_logger().info("[%s] parameters set: %s", comp.component_name, ", ".join(f"{k}={v!r}" for k, v in values.items()))
            return comp.config.asdict()

        if keep_alive:
            return apply()
        return await _cycle(node, L.LifecycleState.INACTIVE, apply)

    async def update_config_parameter(req: dict, stream: Any) -> dict:
        name = req.get("name")
        if not isinstance(name, str):
            raise ValueError("update_config_parameter expects 'name' (str) and 'value'")
        return await update_params({name: req.get("value")}, bool(req.get("keep_alive", True)))

    async def update_config_parameters(req: dict, stream: Any) -> dict:
        values = req.get("values")
        if values is None and "names" in req:
            names, vals = list(req.get("names") or []), list(req.get("values_list") or req.get("new_values") or [])
            if len(names) != len(vals):
                raise ValueError(f"update_config_parameters: {len(names)} names but {len(vals)} values")
            values = dict(zip(names, vals))
        return await update_params(values or {}, bool(req.get("keep_alive", True)))

    async def configure_from_file(req: dict, stream: Any) -> dict:
        path = str(req["path"])

        def apply() -> dict:
            comp.configure(path)
            node.on_config_changed()
            return comp.config.asdict()

        if bool(req.get("keep_alive", True)):
            return apply()
        return await _cycle(node, L.LifecycleState.INACTIVE, apply)

    async def change_topic(req: dict, stream: Any) -> dict:
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

        def swap() -> dict:
            topics[topics.index(old)] = new
            if old in comp._trigger:
                comp._trigger[comp._trigger.index(old)] = new
            return {"old": old.name, "new": new.name, "msg_type": new.type_name}

        return await _cycle(node, L.LifecycleState.UNCONFIGURED, swap)

    async def run_action(req: dict, stream: Any) -> Any:
        from emos.events.action import decode_value

        name = req.get("method", "")
        method = getattr(comp, name, None) if isinstance(name, str) and not name.startswith("__") else None
        if not callable(method):
            raise AttributeError(f"component {node.name!r} ({type(comp).__name__}) has no method {name!r}")
        args = decode_value(req.get("args") or [])
        kwargs = decode_value(req.get("kwargs") or {})
        try:
            return _jsonable(method(*args, **kwargs))
        finally:
            node.publish_status()  # what the action did to the health is seen at once (fallbacks wait for it)

    async def run_step(req: dict, stream: Any) -> bool:
        if node.state != L.LifecycleState.ACTIVE:
            raise RuntimeError(f"component {node.name!r} is {node.state.value}, not active: step not run")
        node._run_step()
        return True

    return {
        "update_config_parameter": update_config_parameter, "update_config_parameters": update_config_parameters,
        "configure_from_file": configure_from_file, "change_topic": change_topic,
        "run_action": run_action, "run_step": run_step,
    }


def request_lifecycle(node: "Node", op: str, wait_time: float = 0.0) -> None:
    """From inside a component (``self.restart()``): ask the supervisor, without waiting for it
    (a restart ends this very process)."""
    loop = node.loop
    if loop is None or node.supervisor_socket is None:
        raise RuntimeError(f"component {node.name!r}: no supervisor to ask for {op}")

    async def ask() -> None:
        from emos.core.rpc import AsyncRpcClient

        client = AsyncRpcClient(node.supervisor_socket)  # type: ignore[arg-type]
        try:
            await client.call("lifecycle", component=node.name, request=op, wait_time=wait_time, wait=False, by="component", timeout=10.0)
        except Exception as exc:
            node.log.error("[%s] %s request to the supervisor failed: %s", node.name, op, exc)
        finally:
            await client.close()

    loop.call_soon_threadsafe(lambda: asyncio.ensure_future(ask()))


class ComponentServices:
    """The live-reconfiguration services of one running component, from Python.

        ComponentServices("controller").update_parameter("loop_rate", 5.0)

    Works from any process of the run (a recipe function, a component, a test given ``ctx``);
    a refused change raises :class:`~emos.core.rpc.RpcError` with the validator's message.
    """

    def __init__(self, component_name: str, ctx: Any = None, timeout: float = 15.0):
        from emos.core.node import control_socket
        from emos.transport.context import current

        self.component_name = component_name
        self.path = control_socket(ctx or current(), component_name)
        self.timeout = timeout

    def _call(self, op: str, **payload: Any) -> Any:
        from emos.core.rpc import RpcClient

        with RpcClient(self.path, timeout=self.timeout) as rpc:
            return rpc.call(op, **payload)

    def change_topic(self, direction: int | str, old_name: str, new_name: str, new_msg_type: str | None = None) -> dict:
        return self._call("change_topic", direction=direction, old_name=old_name, new_name=new_name, new_msg_type=new_msg_type)

    def update_parameter(self, name: str, value: Any, keep_alive: bool = True) -> dict:
        return self._call("update_config_parameter", name=name, value=value, keep_alive=keep_alive)

    def update_parameters(self, values: dict[str, Any], keep_alive: bool = True) -> dict:
        return self._call("update_config_parameters", values=values, keep_alive=keep_alive)

    def configure_from_file(self, path: str, keep_alive: bool = True) -> dict:
        return self._call("configure_from_file", path=path, keep_alive=keep_alive)

    def execute_method(self, method: str, *args: Any, **kwargs: Any) -> Any:
        return self._call("execute_method", method=method, args=list(args), kwargs=kwargs)

    def info(self) -> dict:
        return self._call("info")
