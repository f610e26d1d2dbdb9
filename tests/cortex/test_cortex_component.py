"""Cortex and Memory as real processes under ``emos run``, planning with ``emos serve models``
(the scripted responder): discovery of the run's action servers, component methods and Memory
tools; steps through the events' machinery; a failed step and a component that crashes mid-plan
revise the plan; bad tool calls are refused and never reach a component; Memory queries with
impossible ranges come back refused with the reason."""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

SCRIPT = {"models": ["llama3.2:3b"], "rules": [
    # the revised plan after a failed drive (the cellar does not exist; a crashed robot: stop)
    {"match": "(?s)TASK: drive to the cellar.*robot__drive [^\\n]*kitchen[^\\n]*-> ok", "reply": "DONE: I went to the kitchen instead."},
    {"match": "(?s)TASK: drive to the cellar.*FAILED STEP: [^\\n]*cellar", "tool_call": {"name": "robot__drive", "arguments": {"task": "kitchen"}}},
    {"match": "(?s)TASK: [^\\n]*\\n.*FAILED STEP: [^\\n]*crash", "reply": "I cannot continue: the robot is down."},
    {"match": "(?s)TASK: [^\\n]*\\n.*FAILED STEP: [^\\n]*far", "reply": "I could not get there in time."},
    {"match": "(?s)TASK: [^\\n]*\\n.*(robot__drive|beep|memory__\\w+) [^\\n]*-> ok", "reply": "DONE: finished."},
    {"match": "(?s)TASK: beep twice\\n.*REFUSED: tool 'beep'", "tool_call": {"name": "beep", "arguments": {"times": 2}}},
    {"match": "TASK: beep twice", "reply": '{{"name": "beep", "arguments": {{"times": "two"}}}}'},
    {"match": "TASK: drive to the (\\w+)", "tool_call": {"name": "robot__drive", "arguments": {"task": "{1}"}}},
    {"match": "TASK: where is the (\\w+)", "tool_call": {"name": "memory__locate", "arguments": {"label": "{1}"}}},
    {"match": "Observations:", "reply": "SUMMARY: the robot saw cups and chairs."},
    {"match": "TASK: what will happen", "tool_call": {"name": "memory__temporal_query", "arguments_json": '{{"since_s": -5}}'}},
]}

RECIPE = AGENT_HEADER + """
from emos.actors.agents import Cortex, CortexConfig, Memory, MemoryConfig
from emos.actors.agents.components.vla_interface import (VisionLanguageActionFeedback, VisionLanguageActionGoal,
                                                         VisionLanguageActionResult)


class Robot(BaseComponent):
    \"\"\"A stand-in robot: an action server 'drive' (to rooms it knows) and a method 'beep'.\"\"\"

    def custom_on_configure(self):
        self.create_action_server("robot/drive", VisionLanguageActionGoal, VisionLanguageActionFeedback,
                                  VisionLanguageActionResult, self._drive)
        self.beeps = 0
        self.cancelled = 0

    def _execution_step(self):
        self.health_status.set_healthy()

    def _drive(self, handle):
        room = handle.goal.task
        if room == "crash":
            os._exit(3)  # the component dies in the middle of the step
        if room == "far":  # a drive that does not end: the step times out and Cortex cancels it
            deadline = time.monotonic() + 60
            while not handle.is_cancel_requested and time.monotonic() < deadline:
                time.sleep(0.05)
            self.cancelled += handle.is_cancel_requested
            return VisionLanguageActionResult(success=False, message="cancelled")
        ok = room in ("kitchen", "hall")
        return VisionLanguageActionResult(success=ok, message=f"arrived in the {{room}}" if ok else f"no room called {{room!r}}")

    def cancelled_goals(self) -> int:
        return self.cancelled

    def beep(self, times: int) -> int:
        self.beeps += int(times)
        print(f"[robot] beep x{{times}}", flush=True)
        return self.beeps


robot = Robot(component_name="robot")
task = Topic(name="task", msg_type="String")
answer = Topic(name="answer", msg_type="String")
odom = Topic(name="odom", msg_type="Odometry")
detections = Topic(name="detections", msg_type="Detections")
client = OllamaClient(OllamaModel(name="planner", checkpoint="llama3.2:3b"), port={port})
cortex = Cortex(inputs=[task], outputs=[answer], model_client=client, component_name="cortex",
                config=CortexConfig(max_replans=2, step_timeout=5.0))
cortex.add_tool(robot.beep, {{"type": "function", "function": {{"name": "beep", "description": "Beep some times",
                "parameters": {{"type": "object", "properties": {{"times": {{"type": "integer"}}}}, "required": ["times"]}}}}}})
memory = Memory(position=odom, inputs=[detections], component_name="memory", model_client=client, trigger=0.1,
                config=MemoryConfig(max_records=8))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[robot, cortex, memory])
launcher.bringup()
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("script") / "cortex.yaml"
    path.write_text(yaml.safe_dump(SCRIPT))
    proc = start_server(script=str(path))
    yield proc
    proc.stop()


def _odom(x, y):
    msg = M.Odometry()
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    return msg


def _events(probe: Probe, until: str, timeout: float = 90.0) -> list[dict]:
    got: list[dict] = []

    def done() -> bool:
        got.extend(json.loads(m.data) for m in probe.sub("/cortex/outcome", "String").take())
        return any(e["kind"] == "done" and until in e["text"] for e in got)

    wait_until(done, timeout, what=f"cortex to end its task with {until!r}")
    return got


def test_cortex_plans_with_the_runs_tools_replans_refuses_and_survives_a_crash(tmp_path, server):
    system = SystemUnderTest(tmp_path, RECIPE.format(port=server.port), duration=240).wait_up(
        components=["robot", "cortex", "memory"], timeout=90)
    probe = Probe(system)
    try:
        for topic, kind in (("/cortex/outcome", "String"), ("/cortex/plan", "String"), ("/cortex/steps", "String"), ("/answer", "String")):
            probe.sub(topic, kind)
        # a plain task: the action server of another component, found by discovery
        probe.pub("/task", M.String(data="drive to the kitchen"))
        events = _events(probe, "finished")
        assert [e["kind"] for e in events if e["kind"] in ("outcome", "done")] == ["outcome", "done"]
        assert events[0]["ok"] and "arrived in the kitchen" in events[0]["detail"]
        assert probe.collect("/answer", "String")[0].data == "finished."

        # a failed step: the plan is revised with the failure, then succeeds another way
        probe.pub("/task", M.String(data="drive to the cellar"))
        events = _events(probe, "instead")
        replans = [e for e in events if e["kind"] == "replan"]
        assert len(replans) == 1 and "no room called 'cellar'" in replans[0]["text"]
        plans = [json.loads(m.data) for m in probe.sub("/cortex/plan", "String").take()]
        assert [p["calls"][0]["arguments"]["task"] for p in plans][-2:] == ["cellar", "kitchen"]

        # a bad call is refused (named, with the problem) and never reaches the robot; the fixed one does
        probe.pub("/task", M.String(data="beep twice"))
        events = _events(probe, "finished")
        refused = [e for e in events if e["kind"] == "refused"]
        assert len(refused) == 1 and refused[0]["tool"] == "beep" and "'two' is not of type 'integer'" in refused[0]["problem"]
        outcome = next(e for e in events if e["kind"] == "outcome")
        assert outcome["ok"] and outcome["detail"] == "2"  # robot.beep ran once, in the robot's process, with times=2

        # Memory: its tools are discovered; an impossible range comes back refused with the reason
        probe.pub("/odom", _odom(2.0, 5.5))
        det = M.Detections(labels=["cup"], scores=np.array([0.9]), boxes=np.zeros((1, 4)))

        def seen() -> bool:
            probe.pub("/detections", det)
            probe.pub("/odom", _odom(2.0, 5.5))
            return _located(system)

        wait_until(seen, 30, what="memory to record the cup")
        probe.pub("/task", M.String(data="where is the cup"))
        events = _events(probe, "finished")
        outcome = next(e for e in events if e["kind"] == "outcome")
        assert outcome["ok"] and "'x': 2.0" in outcome["detail"] and "'y': 5.5" in outcome["detail"]
        # bounded: past max_records the oldest records become episodes summarised by the model
        for i in range(14):
            box = M.Detections(labels=[f"box{i}"], scores=np.ones(1), boxes=np.zeros((1, 4)))
            probe.pub("/detections", box)
            wait_until(lambda i=i: _memory(system, "locate", label=f"box{i}")["found"], 10, what=f"memory to record box{i}")
        recent = _memory(system, "temporal_query", since_s=600)
        assert len(recent) <= 9
        assert any(r["kind"] == "episode" and r["text"] == "SUMMARY: the robot saw cups and chairs." for r in recent), recent
        assert _memory(system, "locate", label="cup")["found"]  # the last sighting outlives the fold
        probe.pub("/task", M.String(data="what will happen"))
        events = _events(probe, "task failed")
        outcome = next(e for e in events if e["kind"] == "outcome")
        assert not outcome["ok"] and "since_s=-5 is in the future" in outcome["detail"]

        # a step that runs out of time: failed, and its goal cancelled on the server (the robot stops)
        probe.pub("/task", M.String(data="drive to the far"))
        events = _events(probe, "task failed")
        failed = next(e for e in events if e["kind"] == "outcome")
        assert not failed["ok"] and "no result within step_timeout=5 s; the goal was cancelled" in failed["detail"]
        # The server sees the cancel at its next look (it polls is_cancel_requested), not at once.
        wait_until(lambda: _call(system, "robot", "cancelled_goals") == 1, 20, what="the robot to see its goal cancelled")

        # a component that crashes mid-step: the step fails, the replan prompt carries it
        pid = system.pid("robot")
        probe.pub("/task", M.String(data="drive to the crash"))
        events = _events(probe, "task failed")
        failed = next(e for e in events if e["kind"] == "outcome")
        assert not failed["ok"] and "component 'robot' went away during the step (crashed or restarted)" in failed["detail"]
        assert any(e["kind"] == "replan" and "component 'robot' went away" in e["text"] for e in events)
        wait_until(lambda: system.pid("robot") not in (None, pid), 60, what="the supervisor to restart the robot")
        assert system.pid("cortex") is not None
    finally:
        probe.close()
        assert system.stop() == 0


def _memory(system, method: str, **kwargs):
    return _call(system, "memory", method, **kwargs)


def _call(system, component: str, method: str, **kwargs):
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient

    client = RpcClient(control_socket(system.ctx, component))
    try:
        return client.call("execute_method", method=method, kwargs=kwargs, timeout=10.0)
    finally:
        client.close()


def _located(system) -> bool:
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient

    client = RpcClient(control_socket(system.ctx, "memory"))
    try:
        found = client.call("execute_method", method="locate", kwargs={"label": "cup"}, timeout=10.0)
    finally:
        client.close()
    return isinstance(found, dict) and bool(found.get("found"))
