"""The switch back from ``fallback_to_local()`` to the restarted model server abandons the local
answer in progress (the real SmolLM2 through llama.cpp): the generation stops at its next token,
and the question it was answering goes to the server at once instead of waiting behind it."""
from __future__ import annotations

import threading

import pytest
import yaml

from emos.actors.agents.clients import OllamaClient
from emos.actors.agents.components.llm import LLM, LLMConfig
from emos.actors.agents.errors import GenerationAbandoned
from emos.actors.agents.models import OllamaModel
from emos.actors.agents.server.local_client import LocalLLM, LocalLLMClient
from emos.actors.agents.types import ChatMessage, ChatRequest
from emos.io.topic import Topic
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import wait_until

# Not pure (the real model is loaded, a model server runs), but no component process.
pytestmark = [pytest.mark.process, pytest.mark.timeout(600)]

# A question whose answer is long (hundreds of tokens: minutes on a busy machine).
LONG = ChatRequest(messages=[ChatMessage(role="user", content="Write a long story, at least 400 words, about a robot that cleans a house.")],
                   max_tokens=1500, temperature=0.0)


def _in_thread(fn):
    box: dict = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - the test reads it
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


def test_cancelling_a_local_generation_stops_it_at_its_next_token():
    client = LocalLLMClient(LocalLLM(n_threads=1, n_ctx=1024))
    client.initialize()
    try:
        responder = client._responder
        assert client.cancel_generation() is False  # nothing in progress
        thread, box = _in_thread(lambda: client.chat(LONG))
        wait_until(lambda: responder.tokens_generated >= 5, 300, what="the local model to be answering")
        assert client.cancel_generation() is True
        thread.join(120)
        assert not thread.is_alive(), "the abandoned generation did not stop"
        assert isinstance(box.get("error"), GenerationAbandoned), box
        # After the cancel only the end token was sampled: no more answer was generated.
        assert responder.tokens_after_cancel <= 1, responder.tokens_after_cancel
        # The model answers the next question normally (the cancel does not stick).
        short = ChatRequest(messages=[ChatMessage(role="user", content="Say hello.")], max_tokens=8, temperature=0.0)
        assert client.chat(short).message.content
        assert responder.tokens_after_cancel == 0
    finally:
        client.deinitialize()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("script") / "server.yaml"
    path.write_text(yaml.safe_dump({"models": ["m"], "rules": [{"match": "Write a long story", "reply": "the server's answer"}]}))
    proc = start_server(script=str(path))
    yield proc
    proc.stop()


def test_switching_back_to_the_server_abandons_the_local_answer_and_asks_the_server(server):
    q, a = Topic(name="q", msg_type="String"), Topic(name="a", msg_type="String")
    llm = LLM(inputs=[q], outputs=[a], trigger=q, component_name="talker",
              config=LLMConfig(enable_local_model=True, ncpu_local_model=1, local_model_context=1024),
              model_client=OllamaClient(OllamaModel(name="m", checkpoint="m"), port=server.port))
    local = llm.local_model_client
    try:
        # What fallback_to_local() does in a running component (it refuses an unconfigured one):
        assert llm.change_model_client("local") is True
        assert llm.model_client is local
        local.initialize()
        responder = local._responder
        # The worker's question, answered locally (slowly) when the server comes back:
        thread, box = _in_thread(lambda: llm.call_model(lambda client: client.chat(LONG)))
        wait_until(lambda: responder.tokens_generated >= 5, 300, what="the local model to be answering")
        assert llm.change_model_client("primary") is True  # the switch back to the restarted server
        thread.join(120)
        assert not thread.is_alive(), "the question waited behind the abandoned local answer"
        assert "error" not in box, box
        assert box["value"].message.content == "the server's answer"  # asked again, of the server
        assert responder.tokens_after_cancel <= 1, responder.tokens_after_cancel
        assert llm.model_client_name == "primary"
    finally:
        local.deinitialize()
