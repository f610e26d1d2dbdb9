"""The semantic-routing page's LLM mode (Option 2), ported as recipes/semantic_routing_llm.py and
run with ``emos run`` against the real model server: the router asks the model (the scripted
responder stands in for llama3.2) and sends a movement request to Go-to-X, which reads the goal
from the semantic map, and a question to the general LLM (the model calls no route tool: the
default route, the first one)."""
from __future__ import annotations

import pytest

from emos import msgs as M
from tests.agents.fixtures.server_process import start_server
from tests.agents.test_agents_recipes import _position, _run, _seed_map
from tests.runtime.helpers import REPO

pytestmark = pytest.mark.process


@pytest.fixture(scope="module")
def server():
    import httpx

    server = start_server(script=str(REPO / "recipes" / "models" / "responder.yaml"))
    httpx.post(f"http://127.0.0.1:{server.port}/v1/embeddings", json={"model": "all-minilm-l6-v2", "input": ["warm"]},
               timeout=180).raise_for_status()
    yield server
    server.stop()


def test_llm_mode_router_lets_the_model_pick_the_route(tmp_path, server):
    _seed_map(tmp_path, server)
    system, probe = _run(tmp_path, "semantic_routing_llm.py", server, ["generic_llm", "go_to_x", "smart_router"])
    try:
        probe.sub("/goal_point", "PoseStamped"), probe.sub("/text_out_llm", "String")
        probe.pub("/question", M.String(data="Please go to the kitchen"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=90)[0]) == [1.5, 2.5, 0.0]
        probe.pub("/question", M.String(data="What is the capital of Spain?"))
        assert probe.collect("/text_out_llm", "String", timeout=60)[0].data == "You said: What is the capital of Spain?"
        assert probe.drain("/goal_point", "PoseStamped") == []
        assert probe.drain("/text_out_llm", "String") == []  # the movement request went to Go-to-X only
    finally:
        probe.close()
        assert system.stop() == 0
