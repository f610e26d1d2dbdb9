"""The Monitor's actions on a component of another run: two runs (separate run ids) that share
nothing but Zenoh on loopback. Run B's event fires on run A's topic and calls a method of run A's
worker, sets one of its parameters, calls the main service of run A's switch and restarts the
worker; run A's components observe all four. An action
on a component no run has is logged and the Monitor goes on. Malformed control queries get an
error reply and the helper keeps serving."""
import json
import uuid

import msgpack
import pytest

from tests.runtime.helpers import SystemUnderTest, wait_until
from tests.runtime.test_zenoh_across_runs import _pair
from tests.runtime.test_zenoh_net import _config, _free_port

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

WORKER = """
import json
alarm = Topic(name="alarm", msg_type="Int32", transport="zenoh")

class Worker(BaseComponent):
    def custom_on_activate(self):
        self.n = 0
        with open("activations.txt", "a") as f:
            f.write(f"{os.getpid()}\\n")
    def _execution_step(self):
        self.n += 1
        self.publish(alarm, M.Int32(data=self.n))
        self.health_status.set_healthy()
    def mark(self, value, note="-"):
        with open("marked.txt", "a") as f:
            f.write(json.dumps({"pid": os.getpid(), "value": value, "note": note, "rate": self.config.loop_rate}) + "\\n")
        return value

class Switch(BaseComponent):
    main_srv_type = (M.SetBoolRequest, M.SetBoolResponse)
    def _main_srv_callback(self, request):
        with open("switch.txt", "a") as f:
            f.write(f"{os.getpid()} {request.data}\\n")
        return M.SetBoolResponse(success=True, message="switched")

worker = Worker(component_name="worker", outputs=[alarm])
worker.config.loop_rate = 5
components = [worker]
if os.environ.get("WITH_SWITCH"):
    switch = Switch(component_name="switch")
    switch.run_type = "Server"
    components.append(switch)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=components)
launcher.bringup()
"""

WATCHER = """
from emos import Event, Action
from emos.actions import restart, send_component_service_request, update_parameter

class Idle(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

class Worker(BaseComponent):  # run A's component, named here, not launched by this run
    def mark(self, value, note="-"):
        raise RuntimeError("runs in run A's worker, never here")

class Switch(BaseComponent):  # run A's too
    main_srv_type = (M.SetBoolRequest, M.SetBoolResponse)

class Ghost(BaseComponent):
    def poke(self):
        raise RuntimeError("never called")

alarm = Topic(name="alarm", msg_type="Int32", transport="zenoh")
idle = Idle(component_name="idle")
idle.config.loop_rate = 2
worker = Worker(component_name="worker")
switch = Switch(component_name="switch")
ghost = Ghost(component_name="ghost")
alarmed = Event(alarm.msg.data >= 3, handle_once=True)
haunted = Event(alarm.msg.data >= 2, handle_once=True)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[idle], events_actions={
    haunted: Action(ghost.poke),
    alarmed: [update_parameter(component=worker, param_name="loop_rate", new_value=7.0),  # in order: set, call, restart
              Action(worker.mark, args=(alarm.msg.data,), kwargs={"note": "from B"}),
              send_component_service_request(component=switch, srv_request_msg=M.SetBoolRequest(data=True)),
              restart(component=worker)],
})
launcher.bringup()
"""


def _lines(path):
    try:
        return [line for line in path.read_text().splitlines() if line]
    except FileNotFoundError:
        return []


def test_a_monitor_calls_a_method_a_service_sets_a_parameter_and_restarts_components_of_another_run(tmp_path):
    env_a, env_b = _pair(tmp_path, f"t{uuid.uuid4().hex[:10]}")
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    worker = SystemUnderTest(a, WORKER, env={**env_a, "WITH_SWITCH": "1", "EMOS_NET_CONTROL": "on"}).wait_up(components=["worker", "switch"], timeout=60)
    watcher = None
    try:
        first = worker.pid("worker")
        watcher = SystemUnderTest(b, WATCHER, env=env_b).wait_up(components=["idle", "emos_monitor"], timeout=60)
        assert watcher.ctx.run_id != worker.ctx.run_id
        marked = wait_until(lambda: _lines(a / "marked.txt"), timeout=60, what="run B's action on run A's worker")
        got = json.loads(marked[0])
        assert got["pid"] == first and got["value"] >= 3 and got["note"] == "from B" and got["rate"] == 7.0
        # The restart comes from run B's Monitor, through run A's supervisor: a new incarnation.
        worker.wait_new_pid("worker", first, timeout=60)
        wait_until(lambda: len(_lines(a / "activations.txt")) >= 2, timeout=30, what="the restarted worker's activation")
        assert len(_lines(a / "marked.txt")) == 1  # handle_once: one firing, one call
        assert _lines(a / "switch.txt") == [f"{worker.pid('switch')} True"]  # the service of run A's switch, served there
        # The action on a component that no run has: an error naming event, action and component.
        wait_until(lambda: "ghost.poke() (component ghost) failed: ServiceUnavailable: component 'ghost'" in watcher.output(),
                   timeout=60, what="the Monitor's error about the ghost component")
        assert watcher.state("emos_monitor") == "active" and worker.state("worker") == "active"
    except AssertionError as exc:  # both runs' logs say why
        raise AssertionError(f"{exc}\n--- run A:\n{worker.output()[-3000:]}\n--- run B:\n{watcher.output()[-3000:] if watcher else ''}") from None
    finally:
        if watcher is not None:
            assert watcher.stop() == 0
        assert worker.stop() == 0
    assert "never called" not in watcher.output() and "never here" not in watcher.output() + worker.output()
    assert watcher.leftovers() == [] and worker.leftovers() == []


def test_malformed_control_queries_get_an_error_reply_and_the_helper_keeps_serving(tmp_path):
    from emos.transport import zenoh_net
    from emos.transport.zenoh_control import RemoteControl
    from emos.transport.zenoh_rpc import RemoteServiceError

    group = f"t{uuid.uuid4().hex[:10]}"
    port_run, port_client = _free_port(), _free_port()
    run_conf = _config(tmp_path / "run.json5", f"127.0.0.1:{port_run}", f"127.0.0.1:{port_client}")
    client_conf = _config(tmp_path / "client.json5", f"127.0.0.1:{port_client}", f"127.0.0.1:{port_run}")
    system = SystemUnderTest(tmp_path, WORKER, env={"EMOS_NET_GROUP": group, "EMOS_ZENOH_CONFIG": run_conf, "EMOS_NET_CONTROL": "on"}).wait_up(components=["worker"], timeout=60)
    key = f"emos/{group}/_ctl_/worker"
    try:
        sess = zenoh_net.session(client_conf)
        control = RemoteControl(client_conf, group)
        state = wait_until(lambda: _try(lambda: control.request("worker", {"op": "control", "call": "get_state"}, 5.0)),
                           timeout=60, what="the worker's control over Zenoh")
        assert state["state"] == "active" and state["pid"] == system.pid("worker")

        def error_of(payload):
            replies = list(sess.get(key, payload=payload, timeout=10))
            assert len(replies) == 1 and replies[0].ok is None, payload
            return msgpack.unpackb(replies[0].err.payload.to_bytes(), raw=False)["error"]

        pack = lambda obj: msgpack.packb(obj, use_bin_type=True)  # noqa: E731
        assert "not msgpack" in error_of(b"\xc1 garbage")
        assert "accepts ops" in error_of(pack([1, 2, 3]))
        assert "accepts ops" in error_of(pack({"op": "exit"}))
        assert "'call' must be one of" in error_of(pack({"op": "control", "call": "exit"}))  # not offered
        assert "'call' must be one of" in error_of(pack({"op": "control", "call": "inject_fault"}))
        assert "str keys" in error_of(pack({"op": "control", "call": "run_action", "args": {"timeout": 1}}))
        assert "timeout" in error_of(pack({"op": "control", "call": "get_state", "timeout": float("nan")}))
        assert "'request' must be one of" in error_of(pack({"op": "lifecycle", "request": "kill"}))
        assert "wait_time" in error_of(pack({"op": "lifecycle", "request": "restart", "wait_time": -1}))
        assert "must be bytes" in error_of(pack({"op": "service", "name": "/worker/service", "request": "text"}))
        assert "only a public method" in error_of(pack({"op": "control", "call": "run_action", "args": {"method": "_execution_step", "args": [], "kwargs": {}}}))
        with pytest.raises(RemoteServiceError, match="nope"):
            control.request("worker", {"op": "control", "call": "run_action", "args": {"method": "nope", "args": [], "kwargs": {}}}, 5.0)
        # Still serving, and the worker never restarted.
        assert control.request("worker", {"op": "control", "call": "run_action", "args": {"method": "mark", "args": [41], "kwargs": {}}}, 5.0) == 41
        assert json.loads(_lines(tmp_path / "marked.txt")[0])["value"] == 41
        assert system.state("worker") == "active" and len(_lines(tmp_path / "activations.txt")) == 1
    finally:
        zenoh_net.close_sessions()
        assert system.stop() == 0
    assert system.leftovers() == []


def _try(fn):
    try:
        return fn()
    except Exception:  # noqa: BLE001 - not up yet
        return None


def test_load_time_checks_accept_a_remote_target_only_with_zenoh_and_never_in_a_fallback(monkeypatch, tmp_path):
    """A target outside the launcher: an event's action is accepted when the run uses Zenoh and
    refused, saying how, when it does not; a fallback on it is refused either way."""
    from emos import Action, BaseComponent, Event, Topic
    from emos.actions import restart
    from emos.supervisor.orchestration import Orchestration

    class Arm(BaseComponent):
        def park(self):
            pass

    local, arm = Arm(component_name="local_arm"), Arm(component_name="arm")
    alarm = Topic(name="alarm", msg_type="Int32")
    event = Event(alarm.msg.data > 3)
    orchestration = Orchestration(events_actions=[(event, [Action(arm.park), restart(component=arm)])])
    monkeypatch.delenv("EMOS_ZENOH_CONFIG", raising=False)
    with pytest.raises(ValueError, match=r"targets component 'arm', which is not in this launcher.*emos run --zenoh"):
        orchestration.check([local])
    conf = tmp_path / "z.json5"
    conf.write_text("{}")
    monkeypatch.setenv("EMOS_ZENOH_CONFIG", str(conf))
    orchestration.check([local])  # accepted: the Monitor sends them over Zenoh
    local.on_component_fail(action=restart(component=arm))
    with pytest.raises(ValueError, match="fallbacks act on components of their own run only"):
        Orchestration().check([local])


def test_the_monitor_routes_only_components_outside_its_run_and_needs_zenoh_for_them(monkeypatch):
    import asyncio

    from emos.events.action import ActionError
    from emos.supervisor.monitor_net import ActionRoutes

    routes = ActionRoutes(["planner", "/driver"], timeout=1.0)
    assert not routes.is_remote("planner") and not routes.is_remote("driver") and routes.is_remote("arm")
    monkeypatch.delenv("EMOS_ZENOH_CONFIG", raising=False)
    with pytest.raises(ActionError, match="'arm' is not in this run, and this run does not use Zenoh"):
        asyncio.run(routes.lifecycle("arm", "restart", 0.0))
    routes.close()


def test_a_query_bridge_refuses_queries_beyond_its_limit_at_once_and_serves_again_after(tmp_path):
    """A flood of queries must not spawn threads without end: beyond MAX_CONCURRENT, an
    immediate 'busy' error reply; a slot freed serves again."""
    import threading

    from emos.transport import zenoh_net
    from emos.transport.zenoh_rpc import QueryBridge, _pack

    conf = _config(tmp_path / "solo.json5", f"127.0.0.1:{_free_port()}", f"127.0.0.1:{_free_port()}")
    release = threading.Event()

    class Slow(QueryBridge):
        MAX_CONCURRENT = 1

        def handle(self, query, req):
            release.wait(20)
            query.reply(self.key, _pack({"ok": req["n"]}))

    key = f"emos/t{uuid.uuid4().hex[:8]}/_test_/slow"
    bridge = Slow(key, ("echo",), conf)
    try:
        sess = zenoh_net.session(conf)
        first = sess.get(key, payload=msgpack.packb({"op": "echo", "n": 1}), timeout=20)  # holds the only slot
        # The first query is taken once its thread holds the slot; the second is refused at once.
        busy = wait_until(lambda: (lambda r: r if r and r[0].ok is None else None)(list(sess.get(key, payload=msgpack.packb({"op": "echo", "n": 2}), timeout=5))),
                          timeout=20, what="a busy reply")
        assert "busy" in msgpack.unpackb(busy[0].err.payload.to_bytes())["error"]
        release.set()
        assert msgpack.unpackb(list(first)[0].ok.payload.to_bytes()) == {"ok": 1}
        # The slot is freed when the first query's thread ends, just after its reply went out:
        # a query sent in between is still refused, so ask until one is served.
        again = wait_until(lambda: (lambda r: r if r and r[0].ok is not None else None)(
            list(sess.get(key, payload=msgpack.packb({"op": "echo", "n": 3}), timeout=10))), timeout=30, what="a served query")
        assert msgpack.unpackb(again[0].ok.payload.to_bytes()) == {"ok": 3}
    finally:
        release.set()
        bridge.close()
        zenoh_net.close_sessions()


def test_a_run_serves_its_components_control_only_when_asked(monkeypatch):
    import os

    from emos.transport.zenoh_control import control_enabled

    monkeypatch.delenv("EMOS_NET_CONTROL", raising=False)
    assert control_enabled() is False  # opt-in, as --net-services
    for value, want in (("on", True), ("1", True), ("off", False), ("0", False)):
        monkeypatch.setenv("EMOS_NET_CONTROL", value)
        assert control_enabled() is want
    monkeypatch.setenv("EMOS_NET_CONTROL", "maybe")
    with pytest.raises(ValueError, match="EMOS_NET_CONTROL"):
        control_enabled()
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("EMOS_ZENOH_CONFIG", "EMOS_NET_CONTROL")}
    out = subprocess.run([sys.executable, "-m", "emos", "run", "--no-log", "--net-control", "sensor_demo"],
                         capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 2 and "--net-control serves this run's components over Zenoh: give --zenoh" in out.stderr
