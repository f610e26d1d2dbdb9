"""Issue 40 item 1: `emos serve models --local-llm` answers with the real SmolLM2-135M-Instruct
(llama.cpp) on the OpenAI and Ollama endpoints, plain and streamed, through the project's own
clients. The model is weak; the tests check that its real words pass through every path, not
what it knows."""
from __future__ import annotations

import subprocess
import sys

import pytest

from emos.actors.agents.clients import GenericHTTPClient, OllamaClient
from emos.actors.agents.models import GenericLLM, OllamaModel
from emos.actors.agents.types import ChatMessage, ChatRequest
from tests.agents.fixtures.server_process import start_server

# Bounds a hang only: the processes load a 98 MB model on a machine that may be busy.
pytestmark = [pytest.mark.process, pytest.mark.timeout(900)]


@pytest.fixture(scope="module")
def server():
    proc = start_server("--local-llm", "--threads", "2", script=None)
    yield proc
    proc.stop()


def _ask(text: str, stream: bool = False) -> ChatRequest:
    return ChatRequest(messages=[ChatMessage(role="user", content=text)], stream=stream, temperature=0.0,
                       max_tokens=24, options={"seed": 0})


@pytest.mark.parametrize("name", ["smollm2", "SmolLM2-135M-Instruct.Q4_1", None])
def test_openai_endpoint_answers_with_the_real_model(server, name):
    client = GenericHTTPClient(GenericLLM(name="m", checkpoint=name or "smollm2"), port=server.port, inference_timeout=120)
    try:
        reply = client.chat(_ask("What is the capital of France?"))
        assert reply.message.content and reply.message.content.strip()
        assert reply.usage and reply.usage["completion_tokens"] >= 1  # counted by llama.cpp, not by words
        assert "You said" not in reply.message.content  # not the scripted responder
        pieces = list(client.chat_stream(_ask("Name a colour.", stream=True)))
        text = "".join(p.content for p in pieces)
        assert text.strip() and sum(1 for p in pieces if p.content) >= 2  # token by token
    finally:
        client.close()


def test_ollama_endpoint_answers_plain_and_streamed(server):
    client = OllamaClient(OllamaModel(name="m", checkpoint="smollm2:135m"), port=server.port, inference_timeout=120)
    try:
        client.initialize()  # /api/show and the load call: the model is known by its Ollama name
        reply = client.chat(_ask("Say hello."))
        assert reply.message.content and reply.message.content.strip()
        pieces = list(client.chat_stream(_ask("Count to three.", stream=True)))
        assert "".join(p.content for p in pieces).strip() and sum(1 for p in pieces if p.content) >= 2
        assert pieces[-1].done
    finally:
        client.close()


def test_the_model_is_listed_and_an_image_is_answered_as_unseen(server):
    import json
    import urllib.request

    with urllib.request.urlopen(f"http://127.0.0.1:{server.port}/v1/models", timeout=60) as resp:
        names = {m["id"] for m in json.load(resp)["data"]}
    assert {"SmolLM2-135M-Instruct.Q4_1", "smollm2", "smollm2:135m"} <= names
    import numpy as np

    from emos.actors.agents.types import ImageData

    client = GenericHTTPClient(GenericLLM(name="m", checkpoint="smollm2"), port=server.port, inference_timeout=120)
    try:
        image = ImageData.from_array(np.zeros((8, 8, 3), dtype=np.uint8))
        request = ChatRequest(messages=[ChatMessage(role="user", content="What do you see?", images=[image])],
                              temperature=0.0, max_tokens=16)
        assert client.chat(request).message.content.strip()  # a text-only model: answered, not a 500
    finally:
        client.close()


def test_serve_models_refuses_a_corrupt_gguf_at_start(tmp_path):
    bad = tmp_path / "half.gguf"
    bad.write_bytes(b"GGUF\x03\0\0")
    for extra in (["--gguf", str(bad)], ["--gguf", str(bad), "--local-llm"]):
        done = subprocess.run([sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", "0", *extra],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done
        assert "ready" not in done.stdout
    assert f"GGUF model '{bad}' is truncated" in subprocess.run(
        [sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", "0", "--gguf", str(bad)],
        capture_output=True, text=True, timeout=120).stderr
