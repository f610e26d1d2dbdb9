"""Components: lifecycle, health reported when it changes, event triggers, errors; services and actions across processes."""
import threading
import time

import pytest

from emos import BaseComponent, Topic
from emos import msgs as M
from emos.core.lifecycle import LifecycleState, path_to
from emos.core.node import Node, control_socket
from emos.core.rpc import RpcClient, RpcError
from emos.core.services import ActionCanceled, ActionClient, ServiceClient
from emos.transport.pubsub import Publisher, Subscriber
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process


class Doubler(BaseComponent):
    def custom_on_configure(self):
        self.events = ["configure"]

    def custom_on_activate(self):
        self.events.append("activate")

    def custom_on_deactivate(self):
        self.events.append("deactivate")

    def custom_on_shutdown(self):
        self.events.append("shutdown")

    def _execution_step(self, msg=None, topic=None):
        if msg.data < 0:
            raise ValueError("negative input")
        if msg.data == 0:
            self.health_status.set_fail_algorithm(algorithm_names=["doubling"])
            return
        self.publish(self.out_topics[0], M.Int64(data=2 * msg.data))
        self.health_status.set_healthy()


def run_node(component, ctx):
    node = Node(component, ctx=ctx, supervisor_socket="")
    thread = threading.Thread(target=node.run, kwargs={"install_signal_handlers": False}, daemon=True)
    thread.start()
    wait_until(lambda: control_socket(ctx, component.component_name).exists(), what="control socket")
    return node, thread, RpcClient(control_socket(ctx, component.component_name))


def test_lifecycle_paths():
    S = LifecycleState
    assert [t.value for t in path_to(S.UNCONFIGURED, S.ACTIVE)] == ["configure", "activate"]
    assert [t.value for t in path_to(S.ACTIVE, S.UNCONFIGURED)] == ["deactivate", "cleanup"]
    assert [t.value for t in path_to(S.INACTIVE, S.FINALIZED)] == ["shutdown"]


def test_event_component_lifecycle_health_and_errors(ctx):
    inp, out = Topic(name="in", msg_type="Int64"), Topic(name="out", msg_type="Int64")
    comp = Doubler(component_name="doubler", inputs=[inp], outputs=[out], trigger=inp)
    node, thread, rpc = run_node(comp, ctx)
    status = Subscriber(ctx, "/doubler/status", M.ComponentStatus, queue_size=100)
    results = Subscriber(ctx, "/out", M.Int64)
    feed = Publisher(ctx, "/in", M.Int64)
    try:
        assert rpc.call("get_state")["state"] == "unconfigured"
        feed.publish(M.Int64(data=1))  # ignored: not active yet
        with pytest.raises(RpcError, match="cannot activate from unconfigured"):
            rpc.call("transition", transition="activate")
        assert rpc.call("transition", transition="configure") == "inactive"
        assert rpc.call("transition", transition="activate") == "active"
        status.take()
        reports = []
        for value in (3, 0, -1, 5):
            steps = node.steps
            feed.publish(M.Int64(data=value))
            wait_until(lambda steps=steps: node.steps > steps, what=f"a step for input {value}")
        wait_until(lambda: reports.extend(status.take()) or len(reports) >= 4, what="status of every step")
        codes = [s.status for s in reports if s.lifecycle_state == "active"]
        assert [m.data for m in results.take()] == [6, 10]
        assert M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL in codes
        assert M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL in codes  # the ValueError, caught
        failing = next(s for s in reports if s.status == M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL)
        assert "negative input" in failing.message and failing.src_components == ["doubler"]
        assert node.steps >= 4
        assert rpc.call("transition", transition="deactivate") == "inactive"
        assert comp.events == ["configure", "activate", "deactivate"]
        with pytest.raises(RpcError, match="update_config"):
            rpc.call("nonsense_op")
    finally:
        rpc.call("exit")
        thread.join(10)
    assert not thread.is_alive()
    assert comp.events[-1] == "shutdown"


def test_a_status_is_published_when_a_step_changes_it_not_after_every_step(ctx):
    """The status stream carries changes at once and heartbeats; an unchanged status is not
    repeated after every step (that woke the supervisor at every message a component handled)."""
    inp, out = Topic(name="in", msg_type="Int64"), Topic(name="out", msg_type="Int64")
    comp = Doubler(component_name="doubler", inputs=[inp], outputs=[out], trigger=inp)
    comp.config.heartbeat_rate = 0.1  # one beat every 10 s: none falls inside this test's windows
    node, thread, rpc = run_node(comp, ctx)
    status = Subscriber(ctx, "/doubler/status", M.ComponentStatus, queue_size=100)
    feed = Publisher(ctx, "/in", M.Int64)

    def step_with(value):
        steps = node.steps
        feed.publish(M.Int64(data=value))
        wait_until(lambda: node.steps > steps, what=f"a step for input {value}")

    try:
        rpc.call("transition", transition="configure")
        rpc.call("transition", transition="activate")
        step_with(3)  # healthy, as it was: perhaps one status from activation still on its way
        time.sleep(0.2)
        status.take()
        for _ in range(20):
            step_with(3)
        time.sleep(0.2)
        assert status.take() == []  # twenty healthy steps of a healthy component: nothing new to say
        # The spec's forced publish, from another thread (here the test's): at once, completed.
        comp.health_status_publisher.publish(comp.health_status())
        forced = []
        wait_until(lambda: forced.extend(status.take()) or bool(forced), timeout=5.0, what="the forced status")
        assert [(r.status, r.lifecycle_state, r.pid > 0) for r in forced] == [(M.ComponentStatus.STATUS_HEALTHY, "active", True)]
        with pytest.raises(TypeError, match="'doubler'.*ComponentStatus.*got str"):
            comp.health_status_publisher.publish("healthy")
        started = time.monotonic()
        step_with(0)  # algorithm failure: a change, published by that step, not at the next beat
        reports = []
        wait_until(lambda: reports.extend(status.take()) or bool(reports), timeout=5.0, what="the failure status")
        assert [r.status for r in reports] == [M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL]
        assert reports[0].src_algorithms == ["doubling"] and time.monotonic() - started < 5.0
        step_with(0)  # the same failure again: not repeated
        step_with(3)  # healthy again: a change
        reports = []
        wait_until(lambda: reports.extend(status.take()) or bool(reports), timeout=5.0, what="the recovery status")
        assert [r.status for r in reports] == [M.ComponentStatus.STATUS_HEALTHY]
    finally:
        rpc.call("exit")
        thread.join(10)
    assert not thread.is_alive()


def test_a_node_with_an_input_over_zenoh_does_not_spin_and_still_steps_on_it(ctx, tmp_path, monkeypatch):
    """Zenoh's threads need the interpreter lock to deliver, which a spinning node would hold;
    a node whose inputs are all rings keeps its spin."""
    zenoh_net = pytest.importorskip("emos.transport.zenoh_net")
    pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")
    import json
    import socket
    import uuid

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conf = tmp_path / "z.json5"
    conf.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]},
                                "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}}}))
    monkeypatch.setenv("EMOS_ZENOH_CONFIG", str(conf))
    monkeypatch.setenv("EMOS_NET_GROUP", f"t{uuid.uuid4().hex[:10]}")
    monkeypatch.delenv("EMOS_WAKE_SPIN_US", raising=False)
    net_in = Topic(name="net_in", msg_type="Int64", transport="zenoh")
    local_in = Topic(name="local_in", msg_type="Int64")
    out = Topic(name="out", msg_type="Int64")
    remote = Doubler(component_name="remote", inputs=[net_in], outputs=[out], trigger=net_in)
    local = Doubler(component_name="local", inputs=[local_in], outputs=[Topic(name="out2", msg_type="Int64")], trigger=local_in)
    running = [run_node(remote, ctx), run_node(local, ctx)]
    feed = zenoh_net.ZenohPublisher("/net_in", M.Int64, publisher_id="feeder")
    results = Subscriber(ctx, "/out", M.Int64)
    try:
        for _, _, rpc in running:
            rpc.call("transition", transition="configure")
            rpc.call("transition", transition="activate")
        (node_remote, _, _), (node_local, _, _) = running
        from emos.transport.waker import DEFAULT_SPIN_US

        assert node_remote._waker.spin_ns == 0 and node_local._waker.spin_ns == int(DEFAULT_SPIN_US * 1000)
        got = []
        wait_until(lambda: (feed.publish(M.Int64(data=21)), got.extend(m.data for m in results.take()))[1] or bool(got),
                   what="a step on a message over Zenoh")
        assert set(got) == {42}
    finally:
        feed.close()
        for _, thread, rpc in running:
            rpc.call("exit")
            thread.join(10)
        zenoh_net.close_sessions()


def test_outputs_reach_subscribers_with_values(ctx):
    inp, out = Topic(name="in2", msg_type="Int64"), Topic(name="out2", msg_type="Int64")
    comp = Doubler(component_name="doubler2", inputs=[inp], outputs=[out], trigger=inp)
    node, thread, rpc = run_node(comp, ctx)
    results = Subscriber(ctx, "/out2", M.Int64, queue_size=10)
    feed = Publisher(ctx, "/in2", M.Int64)
    try:
        rpc.call("transition", transition="configure")
        rpc.call("transition", transition="activate")
        for v in (1, 2, 3):
            feed.publish(M.Int64(data=v))
        got = []
        wait_until(lambda: got.extend(m.data for m in results.take()) or len(got) >= 3, what="doubled values")
        assert got == [2, 4, 6]
    finally:
        rpc.call("exit")
        thread.join(10)


class BrokenConfigure(BaseComponent):
    def custom_on_configure(self):
        raise RuntimeError("camera not found")


def test_failed_transition_reports_component_failure_and_returns_to_unconfigured(ctx):
    node, thread, rpc = run_node(BrokenConfigure(component_name="broken"), ctx)
    try:
        with pytest.raises(RpcError, match="configure failed: camera not found"):
            rpc.call("transition", transition="configure")
        state = rpc.call("get_state")
        assert state["state"] == "unconfigured" and state["health"] == "COMPONENT_FAILURE"
    finally:
        rpc.call("exit")
        thread.join(10)


def test_parameters_update_validated_and_methods_execute(ctx):
    class Tunable(BaseComponent):
        def ping(self, x):
            return x + 1

    node, thread, rpc = run_node(Tunable(component_name="tunable"), ctx)
    try:
        import os
        import stat

        assert stat.S_IMODE(os.stat(control_socket(ctx, "tunable")).st_mode) == 0o600
        assert rpc.call("update_config_parameters", values={"loop_rate": 4.0})["loop_rate"] == 4.0
        with pytest.raises(RpcError, match="loop_rate must be in"):
            rpc.call("update_config_parameters", values={"loop_rate": -1.0})
        assert rpc.call("execute_method", method="ping", args=[41]) == 42
        with pytest.raises(RpcError, match="no public method '_execution_step'"):
            rpc.call("execute_method", method="_execution_step")
    finally:
        rpc.call("exit")
        thread.join(10)


SERVICES_RECIPE = """
class Adder(BaseComponent):
    main_srv_type = ("SetBool_Request", "SetBool_Response")
    def custom_on_configure(self):
        self.calls = 0
    def _main_srv_callback(self, request):
        self.calls += 1
        return M.SetBoolResponse(success=request.data, message=f"call {self.calls} in pid {os.getpid()}")

class Counter(BaseComponent):
    main_action_type = ("Int64", "Int64", "String")
    def _main_action_callback(self, goal):
        for i in range(goal.goal.data):
            if goal.is_cancel_requested:
                return M.String(data="canceled")
            goal.publish_feedback(M.Int64(data=i))
            time.sleep(0.02)
        return M.String(data=f"counted to {goal.goal.data}")

adder = Adder(component_name="adder", run_type="Server")
counter = Counter(component_name="counter", run_type="ActionServer")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[adder, counter])
launcher.bringup()
"""


def test_services_and_actions_across_processes(tmp_path):
    system = SystemUnderTest(tmp_path, SERVICES_RECIPE).wait_up(components=["adder", "counter"])
    try:
        srv = ServiceClient("adder/service", "SetBool_Request", "SetBool_Response", ctx=system.ctx)
        wait_until(lambda: (system.run_dir / "srv").exists() and any((system.run_dir / "srv").iterdir()), what="service socket")
        reply = wait_until(lambda: _try(lambda: srv.call(M.SetBoolRequest(data=True))), what="service reply")
        assert reply.success is True and f"pid {system.pid('adder')}" in reply.message
        assert srv.call(M.SetBoolRequest(data=False)).message.startswith("call 2")
        with pytest.raises(TypeError, match="takes SetBoolRequest, got Int64"):
            srv.call(M.Int64(data=1))

        action = ActionClient("counter/action", "Int64", "Int64", "String", ctx=system.ctx)
        feedback = []
        result = action.send_goal(M.Int64(data=5), feedback_callback=lambda fb: feedback.append(fb.data))
        assert result.data == "counted to 5" and feedback == [0, 1, 2, 3, 4]

        outcome = {}
        t = threading.Thread(target=lambda: outcome.update(r=_catch(lambda: action.send_goal(M.Int64(data=500), goal_id="long"))))
        t.start()
        # Cancelled once the server runs it (a cancel before the goal arrived finds nothing).
        wait_until(lambda: action.cancel("long"), what="the long goal running, to cancel it")
        t.join(10)
        assert isinstance(outcome["r"], ActionCanceled)
    finally:
        assert system.stop() == 0
    assert system.leftovers() == []


def _try(fn):
    try:
        return fn()
    except Exception:
        return None


def _catch(fn):
    try:
        return fn()
    except Exception as exc:
        return exc


def test_publish_takes_a_topic_its_name_or_the_name_without_its_slash(ctx):
    """Node.publish looks a declared name up as it is (no normalizing on every message), and
    normalizes anything else; an undeclared output is refused naming the outputs."""
    inp, out = Topic(name="in", msg_type="Int64"), Topic(name="out", msg_type="Int64")
    comp = Doubler(component_name="doubler", inputs=[inp], outputs=[out], trigger=inp)
    node, thread, rpc = run_node(comp, ctx)
    results = Subscriber(ctx, "/out", M.Int64, queue_size=10)
    try:
        rpc.call("transition", transition="configure")
        rpc.call("transition", transition="activate")
        for value, topic in enumerate([out, "/out", "out", " out "]):
            node.publish(topic, M.Int64(data=value))
        got = []
        wait_until(lambda: got.extend(results.take()) or len(got) >= 4, what="four messages on /out")
        assert [m.data for m in got] == [0, 1, 2, 3]
        with pytest.raises(KeyError, match=r"has no output '/nowhere'; outputs: \['/out'\]"):
            node.publish("nowhere", M.Int64(data=1))
        with pytest.raises(ValueError, match="invalid"):
            node.publish("bad//name", M.Int64(data=1))
    finally:
        rpc.call("exit")
        thread.join(10)


def test_the_health_status_revision_moves_only_when_what_it_says_changes():
    """Status.revision drives the status published after a step; set_healthy on a healthy
    status (every step of most components) takes a shortcut that must not hide a change."""
    from emos.core.health import HealthLevel, Status

    status = Status()
    start = status.revision
    for _ in range(3):
        status.set_healthy()
    assert status.revision == start
    status.set_fail_algorithm(["planner"], message="no path")
    assert (status.level, status.algorithms, status.message, status.revision) == (HealthLevel.ALGORITHM_FAILURE, ["planner"], "no path", start + 1)
    status.set_fail_algorithm(["planner"], message="no path")
    assert status.revision == start + 1  # the same failure again
    status.set_healthy()
    assert (status.level, status.algorithms, status.message, status.revision) == (HealthLevel.HEALTHY, [], "", start + 2)
    status.set_general(message="warming up")  # healthy-looking level changes are changes too
    status.set_healthy()
    assert (status.message, status.revision) == ("", start + 4)
    with pytest.raises(TypeError, match="algorithm_names must be a list of str"):
        status.set_fail_algorithm("planner")
