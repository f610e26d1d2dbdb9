"""The component control plane in one home (emos.core.control): its imports, the wire format,
the one way to call a method, and the sync and async clients that wait for a component to
listen. Nodes run for real in threads, on real Unix sockets."""
import ast
import asyncio
import enum
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from emos import BaseComponent
from emos import msgs as M
from emos.core import control as C
from emos.core.node import Node
from emos.core.rpc import RpcClient, RpcConnectionError, RpcError
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber
from tests.runtime.helpers import wait_until

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[2]
# The modules that used to import each other in a circle, and the control plane's own.
TANGLE = {
    "emos.core.component": "emos/core/component.py",
    "emos.core.node": "emos/core/node.py",
    "emos.core.fallbacks": "emos/core/fallbacks.py",
    "emos.core.reconfig": "emos/core/reconfig.py",
    "emos.events.action": "emos/events/action.py",
    "emos.core.control": "emos/core/control.py",
    "emos.core.retry": "emos/core/retry.py",
}


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def runtime_imports(path: Path) -> set[str]:
    """Every module ``path`` imports when it runs: top level and inside functions (lazy ones),
    not under ``if TYPE_CHECKING:``. ``from a import b`` counts as ``a.b`` as well as ``a``."""
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text(), str(path)))
    return found


def module_file(name: str) -> Path | None:
    """The source file of an ``emos`` module (emos.actors, emos.supervisor, emos.chaos live in
    their own folders), or None if ``name`` is not one."""
    parts = name.split(".")
    if parts[0] != "emos":
        return None
    folder = {"actors": "actors", "supervisor": "supervisor", "chaos": "chaos"}
    base = ROOT / folder[parts[1]] if len(parts) > 1 and parts[1] in folder else ROOT / "emos"
    rest = parts[2:] if len(parts) > 1 and parts[1] in folder else parts[1:]
    for candidate in (base.joinpath(*rest).with_suffix(".py") if rest else None, base.joinpath(*rest, "__init__.py")):
        if candidate is not None and candidate.is_file():
            return candidate
    return None


def emos_closure(start: str, skip: set[str]) -> set[str]:
    """Every emos module that importing ``start`` can load (lazy imports included)."""
    seen, todo = set(), [start]
    while todo:
        name = todo.pop()
        path = module_file(name)
        if name in seen or name in skip or path is None:
            continue
        seen.add(name)
        todo.extend(runtime_imports(path))
    return seen


def tangle_edges() -> dict[str, set[str]]:
    return {mod: runtime_imports(ROOT / rel) & set(TANGLE) - {mod} for mod, rel in TANGLE.items()}


def test_the_control_module_imports_none_of_the_runtime_it_serves():
    edges = tangle_edges()
    assert edges["emos.core.control"] <= {"emos.core.retry"}, edges["emos.core.control"]
    assert edges["emos.core.retry"] == set()
    # Nor through any other module: what it imports, and what they import, lazily or not. (The
    # packages it lives in, emos and emos.core, import the component for recipes; they are not
    # the control module's dependencies.)
    reached = emos_closure("emos.core.control", skip={"emos", "emos.core"})
    assert not reached & (set(TANGLE) - {"emos.core.control", "emos.core.retry"}), sorted(reached & set(TANGLE))


def test_no_import_circle_between_component_node_fallbacks_reconfig_and_actions():
    edges = tangle_edges()

    def cycle_from(start: str) -> list[str] | None:
        stack: list[tuple[str, list[str]]] = [(start, [start])]
        while stack:
            mod, path = stack.pop()
            for nxt in edges[mod]:
                if nxt == start:
                    return path + [start]
                if nxt not in path:
                    stack.append((nxt, path + [nxt]))
        return None

    circles = [c for c in (cycle_from(m) for m in TANGLE) if c]
    assert not circles, "import circles (lazy imports included): " + "; ".join(" -> ".join(c) for c in circles)


def test_each_module_imports_first_in_a_fresh_interpreter():
    mods = [m for m in TANGLE if m != "emos.core.retry"]
    for first in mods:
        order = [first] + [m for m in mods if m != first]
        subprocess.run([sys.executable, "-c", "; ".join(f"import {m}" for m in order)], check=True, cwd=ROOT, timeout=120)


# ============================================================================ wire format
class Gear(enum.Enum):
    LOW = "low"
    HIGH = "high"


def test_the_wire_format_round_trips_messages_enums_numpy_and_nests():
    value = [M.Int64(data=7), Gear.HIGH, np.arange(3), np.float32(1.5), {"k": (1, "a", None, b"x")}]
    wire = C.encode_value(value, "test")
    back = C.decode_value(wire)
    assert isinstance(back[0], M.Int64) and back[0].data == 7
    assert back[1] is Gear.HIGH and back[2] == [0, 1, 2] and back[3] == 1.5
    assert back[4] == {"k": [1, "a", None, b"x"]}
    with pytest.raises(C.ActionError, match="test: cannot send a set"):
        C.encode_value({1, 2}, "test")
    assert C.encode_result({1, 2}) == repr({1, 2})  # a result that cannot be sent: its repr
    unknown = {"__emos_enum__": "no.such.module:Thing", "v": 1}
    with pytest.raises(C.ActionError, match="not known in this process"):
        C.decode_value(unknown)
    assert C.decode_result(unknown) == unknown  # an answer is still returned as it came
    assert issubclass(C.ActionError, RuntimeError)
    from emos.events.action import ActionError, decode_value, encode_value

    assert ActionError is C.ActionError and encode_value is C.encode_value and decode_value is C.decode_value


def test_the_zenoh_bridge_accepts_the_old_name_of_execute_method_and_the_socket_does_not():
    from emos.transport.zenoh_control import CONTROL_CALLS

    assert set(C.REMOTE_CALLS) <= set(CONTROL_CALLS) and "run_action" in CONTROL_CALLS
    assert C.LEGACY_REMOTE_CALLS == {"run_action": C.EXECUTE_METHOD}
    assert not {"exit", "transition", "inject_fault", "change_topic"} & set(CONTROL_CALLS)


# ============================================================================ a running node
class Worker(BaseComponent):
    def double(self, msg, factor=2):
        return M.Int64(data=msg.data * factor)

    def gear(self, g):
        return g.value

    def hurt(self):
        self.health_status.set_fail_algorithm(algorithm_names=["hurt"])
        return True

    def _internal(self):
        return "never"


@pytest.fixture
def ctx():
    c = RunContext.create()
    yield c
    c.remove_everything()


def start_node(component, ctx):
    node = Node(component, ctx=ctx, supervisor_socket="")
    thread = threading.Thread(target=node.run, kwargs={"install_signal_handlers": False}, daemon=True)
    thread.start()
    return node, thread


def stop_node(ctx, name, thread):
    with RpcClient(C.control_socket(ctx, name), timeout=10.0) as rpc:
        rpc.call(C.EXIT)
    thread.join(10)
    assert not thread.is_alive()


def test_execute_method_is_the_one_way_to_call_a_method(ctx):
    node, thread = start_node(Worker(component_name="worker"), ctx)
    status = Subscriber(ctx, "/worker/status", M.ComponentStatus, queue_size=100)
    try:
        client = C.ControlClient("worker", ctx, queue_timeout=30.0)  # waits for the node to listen
        assert client.call(C.TRANSITION, transition="configure") == "inactive"
        # Arguments and result in the wire format: a message in, a message out.
        out = client.execute_method("double", M.Int64(data=21), factor=3)
        assert isinstance(out, M.Int64) and out.data == 63
        assert client.execute_method("gear", Gear.LOW) == "low"
        # Plain callers (the CLI, recipes) send plain msgpack and read plain values.
        with RpcClient(C.control_socket(ctx, "worker")) as rpc:
            assert rpc.call(C.EXECUTE_METHOD, method="gear", args=[{"__emos_enum__": f"{__name__}:Gear", "v": "high"}]) == "high"
            with pytest.raises(RpcError, match="no public method '_internal'"):
                rpc.call(C.EXECUTE_METHOD, method="_internal")
            with pytest.raises(RpcError, match="no public method 'nope'"):
                rpc.call(C.EXECUTE_METHOD, method="nope")
            with pytest.raises(RpcError, match="'args' must be a list"):
                rpc.call(C.EXECUTE_METHOD, method="gear", args="x")
            # The duplicate op and the legacy alias are gone from the component's socket.
            for gone in ("run_action", "update_config"):
                with pytest.raises(RpcError, match=f"unknown op '{gone}'"):
                    rpc.call(gone, method="gear", args=[], kwargs={}, values={})
        # What the method did to the health is on the status stream when the call returns.
        status.take()
        assert client.execute_method("hurt") is True
        assert status.latest().status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL
    finally:
        status.close()
        stop_node(ctx, "worker", thread)


def test_the_sync_client_waits_for_a_component_that_is_not_listening_yet_then_names_it(ctx):
    late = Worker(component_name="late")
    starter = threading.Timer(0.3, lambda: holder.append(start_node(late, ctx)))
    holder: list = []
    starter.start()
    try:
        # Sent before the node exists: delivered to it once it listens (bounded by queue_timeout).
        assert C.ControlClient("late", ctx, queue_timeout=60.0).call(C.GET_STATE)["state"] == "unconfigured"
    finally:
        starter.join()
        wait_until(lambda: holder, what="the late node's thread")
        stop_node(ctx, "late", holder[0][1])
    with pytest.raises(RpcConnectionError, match=r"component 'ghost' unreachable for 0.2 s .*get_state not delivered"):
        C.ControlClient("ghost", ctx, queue_timeout=0.2).call(C.GET_STATE)
    with pytest.raises(RpcConnectionError, match="cannot connect"):  # no queue_timeout: one attempt, the socket's error
        C.ControlClient("ghost", ctx).call(C.GET_STATE)


def test_the_async_client_keeps_a_connection_and_reaches_the_next_incarnation(ctx):
    first, thread = start_node(Worker(component_name="w2"), ctx)

    async def scenario():
        links = C.AsyncControlClient(ctx, queue_timeout=60.0)
        try:
            assert (await links.call("w2", C.GET_STATE, 10.0))["pid"] > 0
            out = C.decode_result(await links.execute_method("w2", "double", (M.Int64(data=5),), timeout=10.0))
            assert out.data == 10
            # The component goes away; a new incarnation comes up a little later: the call made
            # in between is delivered to it.
            await links.call("w2", C.EXIT, 10.0)
            await asyncio.get_running_loop().run_in_executor(None, thread.join, 10)
            timer = threading.Timer(0.3, lambda: second.append(start_node(Worker(component_name="w2"), ctx)))
            timer.start()
            try:
                assert (await links.call("w2", C.GET_STATE, 10.0))["state"] == "unconfigured"
            finally:
                timer.join()
            await links.call("w2", C.EXIT, 10.0)
        finally:
            await links.close()
        quick = C.AsyncControlClient(ctx, queue_timeout=0.2)
        with pytest.raises(C.ActionError, match=r"component 'ghost' unreachable for 0.2 s"):
            await quick.call("ghost", C.GET_STATE, 5.0)
        await quick.close()

    second: list = []
    asyncio.run(scenario())
    assert not thread.is_alive()
    wait_until(lambda: second, what="the second incarnation")
    second[0][1].join(10)
    assert not second[0][1].is_alive()


def test_a_private_method_is_refused_when_an_action_is_defined():
    from emos import Action

    worker = Worker(component_name="w3")
    with pytest.raises(ValueError, match=r"w3._internal is not a method an action may call"):
        Action(method=worker._internal)
    assert Action(method=worker.hurt).kind == "component"
    assert Action(method=worker.restart).kind == "lifecycle"
