"""Events, actions, the Monitor and fallbacks in real systems (processes and threads)."""
import json
import os
import signal
import subprocess
import sys

import pytest

from emos.core.node import control_socket
from emos.core.rpc import RpcClient
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

COUNTER = """
from emos import Event, Action
from emos.actions import log, restart
from pathlib import Path

counter = Topic(name="counter", msg_type="Int32")

class Source(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[counter], **kw)
        self.config.loop_rate = 20.0
        self.n = 0
    def _execution_step(self):
        self.n += 1
        self.publish(counter, M.Int32(data=self.n))
        self.health_status.set_healthy()

class Sink(BaseComponent):
    def record(self, value, note="x"):
        with open("sink.txt", "a") as f:
            f.write(f"{os.getpid()} {value} {note}\\n")
        return True
"""


def lines(path):
    return path.read_text().split() if path.exists() else []


@pytest.mark.parametrize("multi", [True, False], ids=["processes", "threads"])
def test_events_run_component_methods_recipe_functions_and_predefined_actions(tmp_path, multi):
    body = COUNTER + f"""
def note(value):
    with open("fn.txt", "a") as f:
        f.write(f"{{os.getpid()}} {{value}}\\n")

src = Source(component_name="source")
sink = Sink(component_name="sink")
def also(value):
    with open("also.txt", "a") as f:
        f.write(f"{{value}}\\n")

once = Event(counter.msg.data >= 5, handle_once=True)
every_tenth = Event((counter.msg.data.is_in([10, 20, 30])) & counter)
at_twenty = Event(counter.msg.data == 20)  # fires on the same message as every_tenth
launcher = Launcher(multi_processing={multi})
launcher.add_pkg(components=[src, sink], events_actions={{
    once: [Action(sink.record, args=(counter.msg.data,), kwargs={{"note": "once"}}), Action(note, args=(counter.msg.data,)), log(msg="EVENT-LOG-LINE")],
    every_tenth: Action(sink.record, args=(counter.msg.data,), kwargs={{"note": "tenth"}}),
    at_twenty: Action(also, args=(counter,)),
}})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source", "sink", "emos_monitor"])
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    if multi:  # the Monitor yields the CPU to the components (Launcher(monitor_nice=5))
        assert os.getpriority(os.PRIO_PROCESS, sut.pid("emos_monitor")) == min(19, ours + 5)
    assert os.getpriority(os.PRIO_PROCESS, sut.proc.pid) == ours  # never the launcher, threaded or not
    sink_file = tmp_path / "sink.txt"
    wait_until(lambda: "30" in lines(sink_file), 20, what="the tenth-message event to fire three times")
    sink_pid = sut.pid("sink")
    sut.stop()
    rows = [r.split() for r in sink_file.read_text().splitlines()]
    assert [r[1:] for r in rows] == [["5", "once"], ["10", "tenth"], ["20", "tenth"], ["30", "tenth"]]
    assert {int(r[0]) for r in rows} == {sink_pid}  # ran inside the sink (its process, or the launcher's in threaded mode)
    fn = (tmp_path / "fn.txt").read_text().split()
    assert fn[1] == "5" and len(fn) == 2  # the recipe function ran once, with the injected value
    if multi:
        assert int(fn[0]) not in (sink_pid, sut.proc.pid)  # in the Monitor's process
    assert sut.output().count("EVENT-LOG-LINE") == 1
    assert (tmp_path / "also.txt").read_text().split() == ["Int32(data=20)"]  # the whole message, bound by its Topic


def test_a_component_that_fails_every_step_is_restarted_until_the_supervisor_gives_up(tmp_path):
    """Issue 9, defect 4: without a declared ladder a component stuck in COMPONENT_FAILURE is
    restarted through the supervisor, whose intensity limits bound it and escalate."""
    body = """
class Broken(BaseComponent):
    def _execution_step(self):
        raise RuntimeError("sensor unplugged")

ok = BaseComponent(component_name="ok")
broken = Broken(component_name="broken")
launcher = Launcher(multi_processing=True, max_restarts=2, max_seconds=30.0)
launcher.add_pkg(components=[ok, broken])
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body)
    code = sut.wait_exit(60)
    out = sut.output()
    assert code == 3, out[-3000:]
    assert "broken" in out and "restarted after:" in out.split("EMOS run")[-1]
    summary = out.split("EMOS run")[-1]
    broken_line = next(line for line in summary.splitlines() if line.strip().startswith("broken"))
    assert "fallback" in broken_line  # restarted by its fallback ladder, and counted so
    assert "supervision gave up" in out


def test_repeated_step_tracebacks_are_rate_limited_with_a_count(tmp_path):
    body = """
from emos.actions import log

class Broken(BaseComponent):
    def _execution_step(self):
        raise ValueError("bad reading")

broken = Broken(component_name="broken")
broken.config.loop_rate = 50.0
broken.config.fallback_rate = 2.0
broken.on_component_fail(action=log(msg="still broken"), max_retries=None)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[broken])
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body, duration=6.5)
    assert sut.wait_exit(40) == 0
    out = sut.output()
    assert out.count("Traceback (most recent call last)") == 1, out[-2000:]
    assert "ValueError: bad reading again (" in out  # one counted line per 5 s window
    assert "no restarts" in out  # a declared handler replaces the default restart
    # 50 failing steps a second, but the unlimited fallback runs at fallback_rate (2 Hz), no faster
    assert 8 <= out.count("emos.actions: still broken") <= 15, out.count("emos.actions: still broken")


LADDER = """
from emos import Action
from emos.actions import restart, log

class Flaky(BaseComponent):
    def _execution_step(self):
        raise RuntimeError("stuck")
    def recover(self):
        with open("recover.txt", "a") as f:
            f.write(f"{os.getpid()}\\n")
        return False

flaky = Flaky(component_name="flaky")
flaky.config.loop_rate = 50.0
flaky.on_component_fail(action=[Action(flaky.recover), restart(component=flaky)], max_retries=2)
flaky.on_giveup(action=log(msg="GIVING-UP-ON-FLAKY"))
launcher = Launcher(multi_processing=MULTI, max_restarts=10, fallback_reset_after=60.0)
launcher.fallback_rate = 20.0
launcher.add_pkg(components=[flaky])
launcher.bringup()
"""


@pytest.mark.parametrize("multi", [True, False], ids=["processes", "threads"])
def test_a_ladder_escalates_gives_up_and_shows_it_in_emos_status(tmp_path, multi):
    sut = SystemUnderTest(tmp_path, LADDER.replace("MULTI", str(multi))).wait_up(components=["flaky"])
    wait_until(lambda: sut.workers()["flaky"].get("health") == "GAVE_UP", 30, what="flaky to give up")
    steps = [(e["handler"], e["step"], e["attempt"]) for e in sut.events() if e["event"] == "fallback"]
    assert steps == [("on_component_fail", 1, 1), ("on_component_fail", 1, 2), ("on_component_fail", 2, 1), ("on_component_fail", 2, 2)]
    assert sum(e["event"] == "gave_up" for e in sut.events()) == 1
    restarts = [e for e in sut.events() if e["event"] == "restarted" and e["child"] == "flaky"]
    assert len(restarts) == 2  # the ladder's restarts went through the supervision tree
    status = subprocess.run([sys.executable, "-m", "emos", "status", "--run", sut.run_dir.name], capture_output=True, text=True, timeout=30)
    assert "GAVE_UP" in status.stdout, status.stdout + status.stderr
    assert len(lines(tmp_path / "recover.txt")) == 2
    sut.stop()
    assert sut.output().count("GIVING-UP-ON-FLAKY") == 1


def test_the_monitor_survives_sigkill_and_keeps_handle_once_fired(tmp_path):
    body = COUNTER + """
def slow(value):
    time.sleep(0.3)  # the Monitor is mid-action most of the time it is killed

class Flaky(BaseComponent):
    def _execution_step(self):
        self.health_status.set_fail_algorithm(algorithm_names=["never_converges"])
    def recover(self):
        return False

src = Source(component_name="source")
sink = Sink(component_name="sink")
flaky = Flaky(component_name="flaky")
flaky.config.fallback_rate = 2.0
flaky.on_algorithm_fail(action=Action(flaky.recover), max_retries=4)
once = Event(counter.msg.data >= 3, handle_once=True)
each = Event(counter)
launcher = Launcher(multi_processing=True, fallback_reset_after=60.0)
launcher.add_pkg(components=[src, sink, flaky], events_actions={
    once: Action(sink.record, args=(counter.msg.data,), kwargs={"note": "once"}),
    each: [Action(sink.record, args=(counter.msg.data,), kwargs={"note": "each"}), Action(slow, args=(counter.msg.data,))],
})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source", "sink", "emos_monitor"])
    sink_file = tmp_path / "sink.txt"
    wait_until(lambda: sink_file.exists() and "once" in sink_file.read_text(), 15, what="the handle_once event")
    for _ in range(2):
        old = sut.pid("emos_monitor")
        os.kill(old, signal.SIGKILL)
        sut.wait_new_pid("emos_monitor", old, 20)
    before = sink_file.read_text().count("each")
    wait_until(lambda: sink_file.read_text().count("each") > before + 5, 15, what="events after the Monitor's restarts")
    assert sink_file.read_text().count("once") == 1
    assert sut.state("source") == "active" and sut.state("sink") == "active"
    # The ladder lives in the supervisor: the Monitor's deaths neither reset nor repeat it.
    wait_until(lambda: any(e["event"] == "gave_up" for e in sut.events()), 20, what="flaky's ladder to be spent")
    attempts = [e["attempt"] for e in sut.events() if e["event"] == "fallback" and e["child"] == "flaky"]
    assert attempts == [1, 2, 3, 4]
    sut.stop()


def test_actions_for_a_restarting_component_are_delivered_and_stats_add_up(tmp_path):
    body = COUNTER + """
src = Source(component_name="source")
sink = Sink(component_name="sink")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[src])
launcher.add_pkg(components=[sink], events_actions={Event(counter): Action(sink.record, args=(counter.msg.data,))})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source", "sink", "emos_monitor"])
    sink_file = tmp_path / "sink.txt"
    wait_until(lambda: len(sink_file.read_text().splitlines()) > 5 if sink_file.exists() else False, 15, what="actions")
    old = sut.pid("sink")
    os.kill(old, signal.SIGKILL)
    new = sut.wait_new_pid("sink", old, 20)
    wait_until(lambda: f"{new} " in sink_file.read_text(), 15, what="actions in the new sink")
    with RpcClient(control_socket(sut.ctx, "source")) as rpc:
        rpc.call("transition", transition="deactivate")  # no more messages: let the queue drain
    with RpcClient(control_socket(sut.ctx, "emos_monitor")) as rpc:
        stats = wait_until(lambda: (lambda s: s if s["fired"] == s["actions_ok"] + s["actions_failed"] else None)(
            rpc.call("execute_method", method="monitor_stats")), 20, what="in-flight actions to finish")
    assert stats["actions_failed"] == 0, stats  # those fired while the sink was down waited for it
    values = [int(line.split()[1]) for line in sink_file.read_text().splitlines()]
    assert set(range(min(values), max(values) + 1)) <= set(values)  # no message's action was lost
    sut.stop()


def test_live_reconfiguration_from_the_cli_validates_and_swaps_topics(tmp_path):
    body = """
a = Topic(name="in_a", msg_type="Int32")
b = Topic(name="in_b", msg_type="Int32")

class Counter(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        with open("got.txt", "a") as f:
            f.write(f"{topic.name} {msg.data}\\n")
        self.health_status.set_healthy()

c = Counter(component_name="counter", inputs=[a], trigger=a)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[c])
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["counter"])
    emos = [sys.executable, "-m", "emos"]
    run = dict(capture_output=True, text=True, timeout=30)
    ok = subprocess.run(emos + ["component", "call", "counter", "update_config_parameter", "name=loop_rate", "value=5", "--run", sut.run_dir.name], **run)
    assert ok.returncode == 0 and json.loads(ok.stdout)["loop_rate"] == 5, ok.stderr
    bad = subprocess.run(emos + ["component", "call", "counter", "update_config_parameters", "names=loop_rate,heartbeat_rate", "values=7,-3", "--run", sut.run_dir.name], **run)
    assert bad.returncode == 1 and "heartbeat_rate" in bad.stderr, bad.stderr
    from emos import ComponentServices
    from emos.core.rpc import RpcError

    counter = ComponentServices("counter", ctx=sut.ctx)
    assert counter.info()["config"]["loop_rate"] == 5  # the refused batch changed nothing
    with pytest.raises(RpcError, match="loop_rate"):
        counter.update_parameter("loop_rate", -1.0)
    assert counter.update_parameter("heartbeat_rate", 20.0, keep_alive=False)["heartbeat_rate"] == 20.0
    assert sut.state("counter") == "active" and counter.info()["config"]["loop_rate"] == 5
    swap = subprocess.run(emos + ["component", "call", "counter", "change_topic", "direction=0", "old_name=in_a", "new_name=in_b", "--run", sut.run_dir.name], **run)
    assert swap.returncode == 0, swap.stderr
    assert sut.state("counter") == "active"
    pub = subprocess.run(emos + ["topic", "pub", "/in_b", "Int32", '{"data": 7}', "--rate", "20", "--count", "20", "--run", sut.run_dir.name], **run)
    assert pub.returncode == 0, pub.stderr + pub.stdout
    wait_until(lambda: (tmp_path / "got.txt").exists() and "/in_b 7" in (tmp_path / "got.txt").read_text(), 15, what="a message on the new input")
    old_pid = sut.pid("counter")
    again = subprocess.run(emos + ["component", "call", "counter", "restart", "--run", sut.run_dir.name], **run)
    assert again.returncode == 0, again.stderr
    sut.wait_new_pid("counter", old_pid, 20)  # through the supervisor: recorded as a requested restart
    assert [e["reason"] for e in sut.events() if e["event"] == "exit" and e["child"] == "counter"] == ["restart_requested"]
    sut.stop()


def test_predefined_actions_services_publish_and_lifecycle(tmp_path):
    body = """
from emos import Event, Action
from emos.actions import (publish_message, trigger_component_service, send_srv_request, restart, stop,
                          update_parameters, send_component_action_server_goal)
from emos.msgs import Bool, SetBoolRequest, SetBoolResponse, String, Float32

flag = Topic(name="flag", msg_type="Bool")
go = Topic(name="go", msg_type="Int32")
chatter = Topic(name="chatter", msg_type="String")

def write(name, text):
    with open(name, "a") as f:
        f.write(text + "\\n")

class Switch(BaseComponent):
    main_srv_type = (SetBoolRequest, SetBoolResponse)
    def _main_srv_callback(self, request):
        write("switch.txt", f"{request.data}")
        return SetBoolResponse(success=True, message="ok")

class Source(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[flag, go], **kw)
        self.config.loop_rate = 10.0
        self.n = 0
    def _execution_step(self):
        self.n += 1
        if self.n == 3:
            self.publish(flag, Bool(data=True))
        self.publish(go, M.Int32(data=self.n))

class Listener(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        write("chatter.txt", msg.data)

class Victim(BaseComponent):
    pass

switch = Switch(component_name="switch")
switch.run_type = "Server"
src = Source(component_name="source")
listener = Listener(component_name="listener", inputs=[chatter], trigger=chatter)
victim = Victim(component_name="victim")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[switch, src, listener, victim], events_actions={
    Event(flag): [trigger_component_service(component=switch),
                               send_srv_request(srv_name="switch/service", srv_type=(SetBoolRequest, SetBoolResponse), srv_request_msg=SetBoolRequest(data=False)),
                               publish_message(topic=chatter, msg=M.String(data="once")),
                               publish_message(topic=chatter, msg=M.String(data="tick"), publish_rate=20.0, publish_period=0.5)],
    Event(go.msg.data == 5): [restart(component=victim), update_parameters(component=listener, params_names=["loop_rate"], new_values=[7.0])],
    Event(go.msg.data == 30): stop(component=victim),
})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["switch", "source", "listener", "victim", "emos_monitor"])
    wait_until(lambda: sut.state("victim") == "inactive", 20, what="the victim to be stopped by the third event")
    assert (tmp_path / "switch.txt").read_text().split() == ["True", "False"]  # request built from the Bool message, then the given one
    chatter = (tmp_path / "chatter.txt").read_text().split()
    assert chatter[0] == "once" and 5 <= chatter.count("tick") <= 12, chatter
    exits = [e for e in sut.events() if e["event"] == "exit" and e["child"] == "victim"]
    # The restart may come before wait_up returns on a busy machine: its pids come from the log.
    started = [e.get("pid") for e in sut.events() if e["event"] == "started" and e["child"] == "victim"]
    assert [e["reason"] for e in exits] == ["restart_requested"] and len(started) == 2 and started[0] != started[1], started
    with RpcClient(control_socket(sut.ctx, "listener")) as rpc:
        assert rpc.call("info")["config"]["loop_rate"] == 7.0
    sut.stop()


def test_stale_data_never_fires(tmp_path):
    body = """
from emos import Event, Action

battery = Topic(name="battery", msg_type="Float32", data_timeout=0.5)
tick = Topic(name="tick", msg_type="Int32")

class Source(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[battery, tick], **kw)
        self.config.loop_rate = 20.0
        self.n = 0
    def _execution_step(self):
        self.n += 1
        if self.n == 10:  # one low-battery reading, then silence: stale after 0.5 s
            self.publish(battery, M.Float32(data=5.0))
        self.publish(tick, M.Int32(data=self.n))

def record(n):
    with open("fired.txt", "a") as f:
        f.write(f"{n}\\n")

src = Source(component_name="source")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[src], events_actions={Event((battery.msg.data < 10.0) & tick): Action(record, args=(tick.msg.data,)),
                                                    Event(~(battery.msg.data > 50.0) & tick): Action(record, args=(-1,))})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source"])
    fired = tmp_path / "fired.txt"
    wait_until(lambda: fired.exists(), 15, what="the low-battery event")
    with RpcClient(control_socket(sut.ctx, "source")) as rpc:
        wait_until(lambda: rpc.call("get_state")["steps"] > 70, 20, what="2.5 s more of ticks")
    sut.stop()
    values = [int(v) for v in fired.read_text().split()]
    ticks = [v for v in values if v > 0]
    assert ticks and min(ticks) >= 10 and max(ticks) <= 10 + 15, ticks  # ~0.5 s of 20 Hz ticks after the reading, never later
    assert values.count(-1) == len(ticks)  # the negated condition is no more true on stale data


def test_a_flood_on_an_event_topic_neither_blocks_the_publisher_nor_wedges_the_monitor(tmp_path):
    body = """
import os

from emos import Event, Action

flood = Topic(name="flood", msg_type="Int32")
done = Topic(name="done", msg_type="Int32")

class Flooder(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[flood, done], **kw)
        self.config.loop_rate = 20.0
        self.n = 0
    def _execution_step(self):
        self.n += 1
        if self.n <= 60:  # 3 s of 500 messages per step, 100 events armed on them
            for k in range(500):
                self.publish(flood, M.Int32(data=k))
        elif self.n == 70:
            self.publish(done, M.Int32(data=1))
        with open("steps.tmp", "w") as f:  # replaced whole: the test never reads a file just truncated
            f.write(str(self.n))
        os.replace("steps.tmp", "steps.txt")

def finished():
    open("finished.txt", "w").write("yes")

events = {Event((flood.msg.data == -k) & flood): Action(finished) for k in range(1, 100)}
events[Event(done)] = Action(finished)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Flooder(component_name="flooder")], events_actions=events)
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["flooder", "emos_monitor"])
    wait_until(lambda: (tmp_path / "finished.txt").exists(), 40, what="the event after the flood")
    assert int((tmp_path / "steps.txt").read_text()) >= 70  # the flooding component kept stepping
    assert sut.state("emos_monitor") == "active"
    assert not [e for e in sut.events() if e["event"] == "exit"]  # nobody died or was restarted
    sut.stop()


def test_a_backlog_on_several_trigger_topics_is_stepped_in_publish_order(tmp_path):
    """A component that wakes to messages waiting on two trigger topics steps through them in
    the order they were published, not all of one topic then all of the other (which would
    pair one topic's newest message with the other's oldest: a state that never existed)."""
    body = """
a = Topic(name="order_a", msg_type="Int32")
b = Topic(name="order_b", msg_type="Int32")

class Source(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[a, b], **kw)
        self.config.loop_rate = 20.0
        self.n = 0
    def _execution_step(self):
        for _ in range(4):  # a burst, alternating topics
            self.n += 1
            self.publish(a if self.n % 2 else b, M.Int32(data=self.n))

class Sink(BaseComponent):
    def __init__(self, **kw):
        super().__init__(inputs=[a, b], trigger=[a, b], **kw)
        self.seen = 0
    def _execution_step(self, msg=None, topic=None):
        self.seen += 1
        with open("order.txt", "a") as f:
            f.write(f"{topic.name} {msg.data}\\n")
        if self.seen % 10 == 1:
            time.sleep(0.2)  # descheduled: several bursts wait on both rings

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Source(component_name="source"), Sink(component_name="sink")])
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source", "sink"])
    order = tmp_path / "order.txt"
    wait_until(lambda: order.exists() and len(order.read_text().split("\n")) > 200, 30, what="200 steps of the sink")
    sut.stop()
    rows = [line.split() for line in order.read_text().splitlines() if line.strip()]
    values = [int(v) for _, v in rows]
    assert all(name == ("/order_a" if v % 2 else "/order_b") for (name, _), v in zip(rows, values)), rows[:20]
    assert values == sorted(values), [v for v, w in zip(values, values[1:]) if w < v][:10]


def test_the_monitor_reads_a_message_only_after_its_defer_time(tmp_path):
    """``Launcher(monitor_defer_ms=...)``: the Monitor waits that long after a wake-up before it
    reads, so the components woken by the same message run first. Every event's action starts at
    least that long after the message was published (the wait is a sleep: a lower bound)."""
    body = """
from emos import Event, Action

stamp = Topic(name="stamp", msg_type="Int64")

class Source(BaseComponent):
    def __init__(self, **kw):
        super().__init__(outputs=[stamp], **kw)
        self.config.loop_rate = 20.0
    def _execution_step(self):
        self.publish(stamp, M.Int64(data=time.monotonic_ns()))
        self.health_status.set_healthy()

class Sink(BaseComponent):
    def record(self, sent_ns):
        with open("latency.txt", "a") as f:
            f.write(f"{(time.monotonic_ns() - sent_ns) / 1e6:.3f}\\n")

src = Source(component_name="source")
sink = Sink(component_name="sink")
launcher = Launcher(multi_processing=True, monitor_defer_ms=15)
launcher.add_pkg(components=[src, sink], events_actions={Event(stamp): Action(sink.record, args=(stamp.msg.data,))})
launcher.bringup()
"""
    sut = SystemUnderTest(tmp_path, body).wait_up(components=["source", "sink", "emos_monitor"])
    out = tmp_path / "latency.txt"
    wait_until(lambda: len(lines(out)) >= 10, 30, what="ten events through a deferring Monitor")
    sut.stop()
    latencies = [float(x) for x in lines(out)]
    assert min(latencies) >= 15.0, latencies


@pytest.mark.parametrize("bad", [-1, 21, "1", True, float("nan")])
def test_monitor_defer_ms_out_of_range_is_refused_at_definition(bad):
    from emos import Launcher

    with pytest.raises(ValueError, match="monitor_defer_ms"):
        Launcher(monitor_defer_ms=bad)
