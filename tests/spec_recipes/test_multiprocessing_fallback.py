"""The multiprocessing page's "Adding Fallback Behavior" (recipes/multiprocessing_agent.py): started
while its model server is down, the components report the failure and keep running their
fallback instead of crashing the recipe; once the server is up they recover and the agent
answers. (The agent's behaviour with the server up: tests/agents/test_agents_recipes.py.)"""
from __future__ import annotations

import re
import shutil
import socket

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPES = REPO / "recipes"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_components_recover_when_the_model_server_comes_back(tmp_path):
    port, resp_port = _free_port(), _free_port()
    shutil.copy(RECIPES / "complete_agent.py", tmp_path / "complete_agent.py")  # the recipe imports it
    env = {"EMOS_MODELS_PORT": str(port), "EMOS_MODELS_RESP_PORT": str(resp_port), "HOME": str(tmp_path)}
    system = SystemUnderTest(tmp_path, (RECIPES / "multiprocessing_agent.py").read_text(), duration=240, env=env)
    server = probe = None
    try:
        system.wait_up(timeout=90)
        # No server: each model component says so and runs its fallback, again and again.
        for name in ("general_q_and_a", "router"):
            wait_until(lambda n=name: len(re.findall(rf"\[{n}\] fallback handler=\S+ .* attempt=\d+", system.output())) >= 2,
                       90, what=f"{name}'s fallback running while the server is down")
        assert system.proc.poll() is None  # the recipe is still up
        server = start_server("--port", str(port), "--resp-port", str(resp_port),
                              script=str(RECIPES / "models" / "responder.yaml"))
        probe = Probe(system)
        probe.sub("/answer", "String")

        def answered() -> bool:
            probe.pub("/question", M.String(data="What is the capital of France?"))
            return any(m.data == "You said: What is the capital of France?" for m in probe.drain("/answer", "String", 1.0))

        wait_until(answered, 120, interval=0.5, what="an answer once the server is back")
    finally:
        if probe is not None:
            probe.close()
        system.stop()
        if server is not None:
            server.stop()
