"""recipes/cortex_agent.py in the simulated house with the scripted planner: Cortex discovers
the navigation, Vision, TextToSpeech and Memory tools of the real components and runs a task
with them. (The full "go to the kitchen ... come back" drive takes about two minutes here; it
was run by hand, see docs/cortex.md. This test gives a task that needs no drive.)"""
from __future__ import annotations

from pathlib import Path

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = [pytest.mark.process, pytest.mark.sim]

ROOT = Path(__file__).resolve().parents[2]


def test_the_recipe_discovers_the_house_tools_and_runs_a_task(tmp_path):
    server = start_server(script=str(ROOT / "actors" / "agents" / "data" / "cortex_house_script.yaml"))
    system = None
    try:
        env = {"EMOS_MODELS_PORT": str(server.port), "EMOS_CORTEX_TASK": "look around and tell me what you see"}
        system = SystemUnderTest(tmp_path, (ROOT / "recipes" / "cortex_agent.py").read_text(), duration=240, env=env).wait_up(
            components=["cortex", "vision", "voice", "memory", "planner", "sim"], timeout=120)
        probe = Probe(system)
        try:
            said = probe.sub("/voice_in", "String")
            answers = probe.collect("/cortex_answer", "String", timeout=120)
            assert answers[0].data == "I told you what I see."
            assert [m.data for m in said.take()][-1].startswith("I see: ")

            from emos.core.node import control_socket
            from emos.core.rpc import RpcClient

            client = RpcClient(control_socket(system.ctx, "cortex"))
            try:
                tools = client.call("execute_method", method="tool_names", timeout=10.0)
            finally:
                client.close()
            assert {"navigate_to", "navigate_to_point", "planner__plan_path", "vision__snapshot", "voice__say",
                    "memory__locate", "memory__temporal_query"} <= set(tools)
            wait_until(lambda: probe.status("cortex").status == M.ComponentStatus.STATUS_HEALTHY, 30, what="cortex healthy")
        finally:
            probe.close()
    finally:
        if system is not None:
            assert system.stop() == 0
        server.stop()
