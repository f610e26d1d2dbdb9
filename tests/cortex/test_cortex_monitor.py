"""Cortex as the launcher's monitor (``launcher.add_pkg(..., monitor=cortex)``), under ``emos run``
with the scripted model (deterministic): a component that reports a failure is observed, Cortex
plans its recovery and the plan's step (a restart through the supervisor) runs; a failed event
action is observed too; and a Cortex that crashes, again and again, stops nothing else: its
group is dropped and the run goes on."""
from __future__ import annotations

import json
import signal

import pytest
import yaml

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

SCRIPT = {"models": ["llama3.2:3b"], "rules": [
    {"match": "(?s)TASK: RECOVER component 'patient'.*restart_component [^\\n]*-> ok", "reply": "DONE: I restarted the patient."},
    {"match": "TASK: RECOVER component 'patient'", "tool_call": {"name": "restart_component", "arguments": {"component": "patient"}}},
    {"match": "TASK: RECOVER component 'bystander'", "reply": "DONE: nothing to do for the bystander."},
]}

RECIPE = AGENT_HEADER + """
from emos import Event
from emos.actions import Action
from emos.actors.agents import Cortex, CortexConfig


class Patient(BaseComponent):
    \"\"\"Healthy until told to fall ill; only a fresh incarnation (a restart) is healthy again.\"\"\"

    def custom_on_configure(self):
        self.ill = False

    def _execution_step(self):
        if self.ill:
            self.health_status.set_fail_algorithm(algorithm_names=["heart"], message="arrhythmia")
        else:
            self.health_status.set_healthy()

    def fall_ill(self) -> bool:
        self.ill = True
        return True

    def take_pulse(self) -> bool:
        return True  # its own fallback: harmless, once; it does not cure


class Bystander(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

    def stumble(self) -> None:
        raise RuntimeError("tripped over the cable")


patient = Patient(component_name="patient")
patient.on_algorithm_fail(action=Action(patient.take_pulse), max_retries=1)
bystander = Bystander(component_name="bystander")
ping = Topic(name="ping", msg_type="String")
client = OllamaClient(OllamaModel(name="planner", checkpoint="llama3.2:3b"), port={port})
cortex = Cortex(model_client=client, component_name="cortex",
                config=CortexConfig(max_replans=1, step_timeout=30.0, monitor_period=0.2, max_recoveries=2))
launcher = Launcher(multi_processing=True, max_restarts=1, max_seconds=120.0)
launcher.add_pkg(components=[patient, bystander], monitor=cortex,
                 events_actions={{Event(ping.msg.data == "stumble"): Action(bystander.stumble)}})
launcher.bringup()
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("script") / "monitor.yaml"
    path.write_text(yaml.safe_dump(SCRIPT))
    proc = start_server(script=str(path))
    yield proc
    proc.stop()


def _observed(probe: Probe, got: list[dict], pred, what: str, timeout: float = 90.0) -> dict:
    def find():
        got.extend(json.loads(m.data) for m in probe.sub("/cortex/observations", "String").take())
        return next((o for o in got if pred(o)), None)

    return wait_until(find, timeout, what=what)


def _call(system, component: str, method: str, **kwargs):
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient

    client = RpcClient(control_socket(system.ctx, component))
    try:
        return client.call("execute_method", method=method, kwargs=kwargs, timeout=10.0)
    finally:
        client.close()


def test_cortex_as_monitor_observes_plans_a_recovery_and_its_crashes_stop_nothing(tmp_path, server):
    system = SystemUnderTest(tmp_path, RECIPE.format(port=server.port), duration=300).wait_up(
        components=["patient", "bystander", "cortex"], timeout=90)
    probe = Probe(system)
    got: list[dict] = []
    try:
        probe.sub("/cortex/observations", "String")
        probe.sub("/cortex/outcome", "String")
        # The Cortex runs in a group of its own, after the components it watches.
        groups = [g["name"] for g in system.tree()["children"]]
        assert groups[-1] == "cortex_monitor", groups
        wait_until(lambda: set(_call(system, "cortex", "monitored_components")) == {"patient", "bystander", "emos_monitor"}, 60,
                   what="cortex to watch the run's components")

        # 1. a component made unhealthy: observed, a recovery planned, its step (a restart) runs
        patient_pid = system.pid("patient")
        assert _call(system, "patient", "fall_ill") is True
        ill = _observed(probe, got, lambda o: o["kind"] == "health" and o["component"] == "patient" and o["trouble"],
                        "cortex to observe the patient's failure")
        assert "ALGORITHM_FAILURE" in ill["text"] and "arrhythmia" in ill["text"]
        recovery = _observed(probe, got, lambda o: o["kind"] == "recovery" and o["component"] == "patient",
                             "cortex to end the patient's recovery")
        assert recovery["success"] and recovery["steps"] == 1, recovery
        new_pid = system.wait_new_pid("patient", patient_pid)
        restarts = [e for e in system.events() if e.get("child") == "patient" and e.get("event") == "exit" and e.get("reason") == "restart_requested"]
        assert restarts and "cortex" in restarts[-1]["detail"], restarts
        outcomes = [json.loads(m.data) for m in probe.sub("/cortex/outcome", "String").take()]
        step = next(o for o in outcomes if o["kind"] == "outcome")
        assert step["ok"] and "restart_component" in step["text"] and step["detail"] == "patient restarted", step
        # the fresh incarnation is healthy: observed as such
        _observed(probe, got, lambda o: o["kind"] == "health" and o["component"] == "patient" and "-> HEALTHY" in o["text"],
                  "cortex to see the patient healthy again")

        # 2. an event's action that fails reaches Cortex as an observation
        probe.pub("/ping", M.String(data="stumble"))
        failed = _observed(probe, got, lambda o: o["kind"] == "event", "cortex to observe the failed event action")
        assert failed["component"] == "bystander" and "tripped over the cable" in failed["text"], failed

        # 3. Cortex crashes (twice: past its group's intensity of 1): nothing else restarts, the run goes on
        bystander_pid, patient_pid = system.pid("bystander"), system.pid("patient")
        cortex_pid = system.pid("cortex")
        import os

        os.kill(cortex_pid, signal.SIGKILL)
        second = system.wait_new_pid("cortex", cortex_pid, timeout=90)
        os.kill(second, signal.SIGKILL)
        wait_until(lambda: "cortex_monitor" not in [g["name"] for g in system.tree()["children"]], 60,
                   what="the root to drop the crashing monitor's group")
        assert system.proc.poll() is None, system.output()
        assert system.pid("bystander") == bystander_pid and system.pid("patient") == patient_pid
        assert system.state("bystander") == "active" and system.state("patient") == "active"
        assert new_pid == patient_pid
    finally:
        probe.close()
        assert system.stop() == 0
