"""Refused connections, servers that never answer, garbage and failing replies: every client
raises the typed error the fallbacks rely on, with the client, model and URL in the message."""
from __future__ import annotations

import inspect
import time
from pathlib import Path

import pytest

from emos.actors.agents.clients import (
    GenericHTTPClient,
    LeRobotClient,
    OllamaClient,
    RoboMLHTTPClient,
    RoboMLRESPClient,
    RoboMLWSClient,
)
from emos.actors.agents.errors import (
    MalformedResponseError,
    ModelClientError,
    ModelConnectionError,
    ModelNotFoundError,
    ModelServerError,
    ModelTimeoutError,
)
from emos.actors.agents.models import GenericLLM, LeRobotPolicy, OllamaModel, TransformersLLM
from emos.actors.agents.types import ChatMessage, ChatRequest, EmbeddingRequest, PolicyObservation

from .fixtures.stub_servers import RawServer, ScriptedHTTP, closed_port, garbage, silent

pytestmark = pytest.mark.unit

FIXTURES = Path(__file__).parent / "fixtures"
FEATURES = {"observation.state": {"dtype": "float32", "shape": [1], "names": ["j"]}}


def chat() -> ChatRequest:
    return ChatRequest(messages=[ChatMessage("user", "hello")])


def make(kind: str, port: int, **kw):
    if kind == "generic":
        return GenericHTTPClient(GenericLLM(name="g"), port=port, **kw)
    if kind == "ollama":
        return OllamaClient(OllamaModel(name="o"), port=port, **kw)
    if kind == "roboml_http":
        return RoboMLHTTPClient(TransformersLLM(name="r"), port=port, **kw)
    if kind == "roboml_ws":
        return RoboMLWSClient(TransformersLLM(name="w"), port=port, **kw)
    if kind == "roboml_resp":
        return RoboMLRESPClient(TransformersLLM(name="s"), port=port, **kw)
    return LeRobotClient(LeRobotPolicy(name="l", features=FEATURES, policy_device="cpu"), port=port, **kw)


def infer(client):
    if isinstance(client, LeRobotClient):
        return client.inference(PolicyObservation({"j": 0.0}))
    return client.inference(chat())


KINDS = ["generic", "ollama", "roboml_http", "roboml_ws", "roboml_resp", "lerobot"]


@pytest.mark.parametrize("kind", KINDS)
def test_refused_connection_is_a_connection_error(kind):
    port = closed_port()
    client = make(kind, port)
    with pytest.raises(ModelConnectionError) as info:
        client.check_connection()
    assert str(port) in str(info.value) and type(client).__name__ in str(info.value)
    with pytest.raises(ModelConnectionError):
        infer(client)
    client.close()


@pytest.mark.parametrize("kind", KINDS)
def test_a_server_that_never_answers_times_out(kind):
    server = RawServer(silent)
    try:
        client = make(kind, server.port, inference_timeout=0.5, connect_timeout=0.5)
        started = time.monotonic()
        with pytest.raises((ModelTimeoutError, ModelConnectionError)) as info:
            infer(client)
        elapsed = time.monotonic() - started
        # The configured 0.5 s timeouts ended the call, not the default: that one ends it at 30 s
        # at the earliest, so anything sooner is the configured one, however late a loaded
        # machine runs the 0.5 s timer (no wall-clock budget beyond that distinction).
        default = inspect.signature(type(client)).parameters["inference_timeout"].default
        assert elapsed < default, f"{kind}: {elapsed:.1f} s, so the default {default} s timeout ended the call"
        # HTTP, RESP and gRPC calls get through TCP and then wait: that is a timeout, not a refusal.
        # The WebSocket handshake itself is what hangs for the WS client: bounded by connect_timeout.
        if kind in ("generic", "ollama", "roboml_http", "roboml_resp"):
            assert isinstance(info.value, ModelTimeoutError)
        client.close()
    finally:
        server.close()


@pytest.mark.parametrize("kind", ["generic", "ollama", "roboml_http", "roboml_ws", "roboml_resp"])
def test_garbage_bytes_are_a_malformed_response(kind):
    server = RawServer(garbage)
    try:
        client = make(kind, server.port, inference_timeout=2.0)
        with pytest.raises((MalformedResponseError, ModelConnectionError)) as info:
            infer(client)
        if kind != "roboml_ws":  # websockets reports a failed handshake either way
            assert isinstance(info.value, MalformedResponseError), info.value
        client.close()
    finally:
        server.close()


def test_http_error_status_is_a_server_error_with_status_and_body():
    server = ScriptedHTTP({("POST", "/v1/chat/completions"): (500, "text/plain", b"CUDA out of memory")})
    try:
        client = make("generic", server.port)
        with pytest.raises(ModelServerError) as info:
            client.inference(chat())
        assert info.value.status == 500 and "CUDA out of memory" in info.value.body
        assert "/v1/chat/completions" in str(info.value)
    finally:
        server.close()


def test_non_json_body_is_malformed():
    server = ScriptedHTTP({("POST", "/api/chat"): (200, "text/html", b"<html>proxy login</html>")})
    try:
        with pytest.raises(MalformedResponseError, match="JSON body"):
            make("ollama", server.port).inference(chat())
    finally:
        server.close()


def test_json_of_the_wrong_shape_is_malformed():
    server = ScriptedHTTP({("POST", "/v1/chat/completions"): (200, "application/json", b'{"result": "hi"}')})
    try:
        with pytest.raises(MalformedResponseError, match="choices"):
            make("generic", server.port).inference(chat())
    finally:
        server.close()


def test_transient_statuses_are_retried_up_to_max_retries():
    server = ScriptedHTTP({("POST", "/v1/chat/completions"): (503, "application/json", b'{"error": "busy"}')})
    try:
        client = make("generic", server.port, max_retries=2, retry_backoff=0.01)
        with pytest.raises(ModelServerError):
            client.inference(chat())
        assert server.hits[("POST", "/v1/chat/completions")] == 3
    finally:
        server.close()


def test_client_errors_are_not_retried():
    server = ScriptedHTTP({("POST", "/v1/chat/completions"): (400, "application/json", b'{"error": "bad"}')})
    try:
        client = make("generic", server.port, max_retries=3, retry_backoff=0.01)
        with pytest.raises(ModelServerError):
            client.inference(chat())
        assert server.hits[("POST", "/v1/chat/completions")] == 1
    finally:
        server.close()


def test_fixture_bodies_flow_through_the_real_clients():
    body = (FIXTURES / "openai_chat_response_tool_calls.json").read_bytes()
    sse = (FIXTURES / "openai_chat_stream_tool_calls.sse").read_bytes()
    embeddings = (FIXTURES / "openai_embeddings_response.json").read_bytes()
    server = ScriptedHTTP({("POST", "/v1/chat/completions"): (200, "application/json", body),
                           ("POST", "/v1/embeddings"): (200, "application/json", embeddings),
                           ("GET", "/v1/models"): (200, "application/json", (FIXTURES / "openai_models.json").read_bytes())})
    try:
        client = make("generic", server.port)
        client.check_connection()
        client.initialize()  # "gpt-4o" is in the fixture's model list
        assert client.inference(chat()).message.tool_calls[0].arguments == {"place": "kitchen"}
        vectors = client.inference(EmbeddingRequest(["a", "b"])).embeddings
        assert vectors.tolist()[0] == pytest.approx([0.6, 0.0, 0.8])  # reordered by index
        server.routes[("POST", "/v1/chat/completions")] = (200, "text/event-stream", sse)
        final = list(client.chat_stream(chat()))[-1]
        assert [c.name for c in final.tool_calls] == ["go_to", "stop"]
        missing = GenericHTTPClient(GenericLLM(name="g", checkpoint="gpt-9"), port=server.port)
        with pytest.raises(ModelNotFoundError, match="gpt-9"):
            missing.initialize()
    finally:
        server.close()


def test_ollama_error_statuses_from_fixture_server():
    tags = (FIXTURES / "ollama_tags.json").read_bytes()
    server = ScriptedHTTP({("GET", "/api/tags"): (200, "application/json", tags),
                           ("POST", "/api/show"): (404, "application/json", b'{"error": "model not found"}'),
                           ("POST", "/api/pull"): (500, "application/json", b'{"error": "pull model manifest: file does not exist"}')})
    try:
        client = make("ollama", server.port)
        client.check_connection()
        assert client.list_models() == ["llama3.2:3b"]
        with pytest.raises(ModelServerError, match="file does not exist"):
            client.initialize()  # show says 404, so it pulls; the pull fails
        assert server.hits[("POST", "/api/pull")] == 1
        client.pull_if_missing = False
        with pytest.raises(ModelNotFoundError):
            client.initialize()
    finally:
        server.close()


def test_every_error_is_a_model_client_error():
    for cls in (ModelConnectionError, ModelTimeoutError, ModelServerError, MalformedResponseError, ModelNotFoundError):
        assert issubclass(cls, ModelClientError)
