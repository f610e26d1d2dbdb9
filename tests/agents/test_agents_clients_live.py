"""Every client against the local model server over real sockets (HTTP, SSE, NDJSON,
WebSocket, RESP, gRPC), with real embeddings, espeak-ng speech and PocketSphinx STT."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from emos.actors.agents.clients import (
    GenericHTTPClient,
    LeRobotClient,
    OllamaClient,
    RoboMLHTTPClient,
    RoboMLRESPClient,
    RoboMLWSClient,
    client_from_serialized,
)
from emos.actors.agents.errors import ModelClientError, ModelNotFoundError, ModelServerError
from emos.actors.agents.models import (
    GenericLLM,
    GenericMLLM,
    GenericSTT,
    GenericTTS,
    LeRobotPolicy,
    OllamaModel,
    SpeechT5,
    TransformersLLM,
    TransformersMLLM,
    VisionModel,
    Whisper,
)
from emos.actors.agents.types import (
    ChatMessage,
    ChatRequest,
    DetectionRequest,
    EmbeddingRequest,
    PolicyObservation,
    SpeechRequest,
    ToolSpec,
    TranscriptionRequest,
)

from .fixtures.server_process import start_server

pytestmark = pytest.mark.process

GO_TO = ToolSpec(name="go_to", description="Drive to a place",
                 parameters={"type": "object", "properties": {"place": {"type": "string"}}, "required": ["place"]})


@pytest.fixture(scope="module")
def server():
    proc = start_server()
    yield proc
    assert proc.stop() == 143  # a clean SIGTERM exit (128 + 15)


def ask(text: str, **kw) -> ChatRequest:
    return ChatRequest(messages=[ChatMessage("system", "You are a robot."), ChatMessage("user", text)], **kw)


# ------------------------------------------------------------------ OpenAI-compatible


def test_generic_chat_plain_and_streamed(server):
    client = GenericHTTPClient(GenericLLM(name="llm", checkpoint="emos-scripted"), port=server.port)
    client.check_connection()
    client.initialize()
    reply = client.inference(ask("hello there"))
    assert reply.message.content == "Hello! I am a robot." and reply.finish_reason == "stop"
    chunks = list(client.inference(ask("please say banana", stream=True)))
    assert len(chunks) > 2 and "".join(c.content for c in chunks) == "You said: please say banana"
    assert chunks[-1].done and chunks[-1].usage["completion_tokens"] == 5
    client.deinitialize()


def test_generic_tool_call_round_trip(server):
    client = GenericHTTPClient(GenericLLM(name="llm", checkpoint="emos-scripted"), port=server.port)
    request = ask("go to the kitchen", tools=[GO_TO])
    reply = client.inference(request)
    call = reply.message.tool_calls[0]
    assert (call.name, call.arguments, reply.finish_reason) == ("go_to", {"place": "kitchen"}, "tool_calls")
    streamed = list(client.inference(ask("go to the garage", tools=[GO_TO], stream=True)))
    assert streamed[-1].tool_calls[0].arguments == {"place": "garage"}  # fragments reassembled
    # Without the tool on offer the model cannot call it.
    assert client.inference(ask("go to the kitchen")).message.tool_calls == []
    follow_up = ChatRequest(messages=[*request.messages, reply.message,
                                      ChatMessage("tool", "arrived", tool_call_id=call.id, name="go_to")], tools=[GO_TO])
    assert client.inference(follow_up).message.content == "Tool go_to returned: arrived"


def test_generic_multimodal_request_carries_the_image(server):
    client = GenericHTTPClient(GenericMLLM(name="vlm", checkpoint="emos-scripted"), port=server.port)
    image = np.zeros((8, 8, 3), np.uint8)
    image[..., 0] = 255
    reply = client.inference(ChatRequest(messages=[ChatMessage("user", "what colour is it?", images=[image])]))
    assert reply.message.content == "It is red."


def test_generic_unknown_model_is_not_found(server):
    client = GenericHTTPClient(GenericLLM(name="llm", checkpoint="gpt-4o"), port=server.port)
    with pytest.raises(ModelNotFoundError, match="gpt-4o"):
        client.initialize()
    with pytest.raises(ModelServerError) as info:
        client.inference(ask("hi"))
    assert info.value.status == 404


def test_generic_embeddings_are_real_sentence_embeddings(server):
    client = GenericHTTPClient(GenericLLM(name="emb", checkpoint="all-MiniLM-L6-v2"), port=server.port,
                               inference_timeout=120)
    vectors = client.embed(["go to the kitchen", "drive into the kitchen", "the stock market fell today"]).embeddings
    assert vectors.shape == (3, 384)
    assert np.allclose(np.linalg.norm(vectors, axis=1), 1.0, atol=1e-4)
    assert vectors[0] @ vectors[1] > vectors[0] @ vectors[2] + 0.2


def test_generic_speech_then_transcription_round_trip(server):
    tts = GenericHTTPClient(GenericTTS(name="tts", voice="alloy", speed=0.8), port=server.port)
    speech = tts.inference(SpeechRequest("one two three four five"))
    assert speech.mime_type == "audio/wav" and speech.audio[:4] == b"RIFF" and speech.audio[8:12] == b"WAVE"
    stt = GenericHTTPClient(GenericSTT(name="stt", language="en"), port=server.port, inference_timeout=60)
    text = stt.inference(TranscriptionRequest(speech.audio)).text
    assert "three" in text and "four" in text
    with pytest.raises(ModelServerError) as info:  # the packaged STT model is English only
        stt.inference(TranscriptionRequest(speech.audio, language="fr"))
    assert info.value.status == 501


# ------------------------------------------------------------------ Ollama


def test_ollama_lifecycle_chat_stream_and_tools(server):
    client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b", options={"temperature": 0.3}),
                          port=server.port)
    client.check_connection()
    assert "llama3.2:3b" in client.list_models()
    assert "tools" in client.show()["capabilities"]
    client.initialize()  # show + preload (keep_alive)
    assert client.inference(ask("hello")).message.content == "Hello! I am a robot."
    chunks = list(client.inference(ask("go to the lab", tools=[GO_TO], stream=True)))
    assert chunks[-1].done and chunks[-1].tool_calls[0].arguments == {"place": "lab"}
    text = "".join(c.content for c in client.inference(ask("count to three", stream=True)))
    assert text == "You said: count to three"
    client.deinitialize()  # keep_alive 0 unload


def test_ollama_images_and_max_tokens(server):
    client = OllamaClient(OllamaModel(name="qwen", checkpoint="qwen2.5vl:latest"), port=server.port)
    reply = client.inference(ChatRequest(messages=[ChatMessage("user", "What color?", images=[np.zeros((4, 4, 3), np.uint8)])]))
    assert reply.message.content == "It is red."
    short = client.inference(ask("one two three four five six", max_tokens=3))
    assert short.message.content == "You said: one " and short.finish_reason == "length"


def test_ollama_pull_succeeds_only_for_local_models(server):
    OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port=server.port).pull()
    missing = OllamaClient(OllamaModel(name="big", checkpoint="llama3.1:405b"), port=server.port)
    with pytest.raises(ModelNotFoundError):
        missing.show()
    with pytest.raises(ModelServerError, match="no downloads"):
        missing.initialize()


def test_ollama_embeddings(server):
    client = OllamaClient(OllamaModel(name="emb", checkpoint="all-minilm"), port=server.port, inference_timeout=120)
    vectors = client.inference(EmbeddingRequest(["red apple", "green apple"])).embeddings
    assert vectors.shape == (2, 384) and vectors.dtype == np.float32


# ------------------------------------------------------------------ RoboML (HTTP, WebSocket, RESP)


def stick_person(height: int = 400, width: int = 300) -> np.ndarray:
    """A dark stick figure on a light background: enough for OpenCV's HOG people detector."""
    import cv2

    image = np.full((height, width, 3), 210, np.uint8)
    ink, cx = (30, 30, 30), width // 2
    cv2.circle(image, (cx, 60), 14, ink, -1)
    cv2.fillPoly(image, [np.array([(cx - 24, 78), (cx + 24, 78), (cx + 18, 158), (cx - 18, 158)])], ink)
    for (x0, y0, x1, y1, thickness) in ((-22, 84, -34, 150, 9), (22, 84, 34, 150, 9),
                                        (-10, 156, -15, 245, 13), (10, 156, 15, 245, 13)):
        cv2.line(image, (cx + x0, y0), (cx + x1, y1), ink, thickness)
    return image


def roboml(kind, model, server):
    if kind is RoboMLRESPClient:
        return kind(model, port=server.resp_port)
    return kind(model, port=server.port)


@pytest.mark.parametrize("kind", [RoboMLHTTPClient, RoboMLWSClient, RoboMLRESPClient])
def test_roboml_llm_node_lifecycle(kind, server):
    client = roboml(kind, TransformersLLM(name=f"llm_{kind.__name__}"), server)
    client.check_connection()
    client.initialize()
    assert client.inference(ask("hello")).message.content == "Hello! I am a robot."
    chunks = list(client.inference(ask("stream this please", stream=True)))
    assert "".join(c.content for c in chunks) == "You said: stream this please" and chunks[-1].done
    if kind is not RoboMLRESPClient:
        assert len(chunks) > 2  # really streamed, piece by piece
    with pytest.raises(ModelClientError, match="tool calling"):
        client.inference(ask("go to the kitchen", tools=[GO_TO]))
    client.deinitialize()
    with pytest.raises(ModelServerError):  # the node is gone
        client.inference(ask("hello"))


@pytest.mark.parametrize("kind", [RoboMLHTTPClient, RoboMLWSClient, RoboMLRESPClient])
def test_roboml_speech_vision_and_multimodal_nodes(kind, server):
    tts = roboml(kind, SpeechT5(name=f"tts_{kind.__name__}"), server)
    tts.initialize()
    audio = tts.inference(SpeechRequest("one two three four five")).audio
    assert audio[:4] == b"RIFF"
    stt = roboml(kind, Whisper(name=f"stt_{kind.__name__}"), server)
    stt.initialize()
    assert "three" in stt.inference(TranscriptionRequest(audio)).text
    vision = roboml(kind, VisionModel(name=f"det_{kind.__name__}"), server)
    vision.initialize()
    result = vision.inference(DetectionRequest(images=[stick_person(), np.full((128, 64, 3), 128, np.uint8)], threshold=0.5))
    person, empty = result.detections
    assert "person" in person.labels and np.all(person.scores >= 0.5)
    x1, y1, x2, y2 = person.boxes[person.labels.index("person")]
    assert x1 < 150 < x2 and y1 < 120 < y2  # the box covers the figure
    assert empty.labels == [] and empty.boxes.shape == (0, 4)
    mllm = roboml(kind, TransformersMLLM(name=f"mllm_{kind.__name__}"), server)
    mllm.initialize()
    reply = mllm.inference(ChatRequest(messages=[ChatMessage("user", "what colour?", images=[np.ones((4, 4, 3), np.uint8)])]))
    assert reply.message.content == "It is red."
    with pytest.raises(TypeError, match="cannot answer"):
        tts.inference(ask("hello"))
    for client in (tts, stt, vision, mllm):
        client.deinitialize()


# ------------------------------------------------------------------ LeRobot (gRPC)


def test_lerobot_policy_round_trip(server):
    features = {"observation.state": {"dtype": "float32", "shape": [2], "names": ["elbow", "gripper"]},
                "observation.images.front": {"dtype": "video", "shape": [8, 8, 3], "names": ["h", "w", "c"]}}
    client = LeRobotClient(LeRobotPolicy(name="vla", features=features, actions_per_chunk=4, policy_device="cpu"),
                           port=server.lerobot_port)
    client.check_connection()
    client.initialize()
    camera = np.random.default_rng(0).integers(0, 255, (8, 8, 3), dtype=np.uint8)
    chunk = client.inference(PolicyObservation({"elbow": 0.25, "gripper": -0.5, "observation.images.front": camera,
                                                "task": "pick the cube"}, timestep=10))
    assert chunk.actions.shape == (4, 2) and np.allclose(chunk.actions, [[0.25, -0.5]] * 4)
    assert chunk.timesteps.tolist() == [10, 11, 12, 13] and np.all(np.diff(chunk.timestamps) > 0)
    assert client.receive_actions(timeout=3.0) is None  # nothing new observed: an empty reply
    with pytest.raises(ModelServerError, match="lacks joints"):
        client.inference(PolicyObservation({"elbow": 0.1}))
    client.deinitialize()


# ------------------------------------------------------------------ rebuilt in another process


CHILD = """
import json, sys
from emos.actors.agents.clients import client_from_serialized
from emos.actors.agents.types import ChatMessage, ChatRequest
client = client_from_serialized(json.loads(sys.stdin.read()))
client.check_connection()
reply = client.inference(ChatRequest(messages=[ChatMessage("user", "greetings from the child")]))
print(json.dumps({"type": type(client).__name__, "model": client.model_name, "reply": reply.message.content}))
"""


@pytest.mark.parametrize("kind", ["generic", "ollama", "roboml_ws", "roboml_resp"])
def test_serialized_client_is_rebuilt_and_works_in_a_subprocess(kind, server):
    clients = {
        "generic": lambda: GenericHTTPClient(GenericLLM(name="g", checkpoint="emos-scripted"), port=server.port,
                                             api_key="sk-test", max_retries=2),
        "ollama": lambda: OllamaClient(OllamaModel(name="o", checkpoint="llama3.2:3b", options={"num_ctx": 2048}),
                                       port=server.port, inference_timeout=12),
        "roboml_ws": lambda: RoboMLWSClient(TransformersLLM(name="child_ws"), port=server.port),
        "roboml_resp": lambda: RoboMLRESPClient(TransformersLLM(name="child_resp"), port=server.resp_port),
    }
    client = clients[kind]()
    if kind.startswith("roboml"):
        client.initialize()
    data = client.serialize()
    wire = json.dumps(data)
    rebuilt_here = client_from_serialized(json.loads(wire))
    assert rebuilt_here.serialize() == data
    done = subprocess.run([sys.executable, "-c", CHILD], input=wire, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result == {"type": type(client).__name__, "model": client.model_name, "reply": "You said: greetings from the child"}


def test_api_key_comes_from_argument_or_environment(monkeypatch):
    monkeypatch.setenv("OPENAI_API_KEY", "sk-env")
    from_env = GenericHTTPClient(GenericLLM(name="g"))
    assert from_env.api_key == "sk-env" and from_env.serialize()["api_key"] is None  # env keys are not copied
    assert GenericHTTPClient(GenericLLM(name="g"), api_key="sk-arg").api_key == "sk-arg"
    monkeypatch.delenv("OPENAI_API_KEY")
    assert GenericHTTPClient(GenericLLM(name="g")).api_key is None


def test_clients_reject_models_they_cannot_serve():
    with pytest.raises(TypeError, match="OllamaClient cannot serve a GenericLLM"):
        OllamaClient(GenericLLM(name="g"))
    with pytest.raises(TypeError, match="RoboMLHTTPClient cannot serve a OllamaModel"):
        RoboMLHTTPClient(OllamaModel(name="o"))
    with pytest.raises(ValueError, match="port"):
        GenericHTTPClient(GenericLLM(name="g"), port=70000)


def test_base_urls_from_hosts_and_full_urls():
    assert GenericHTTPClient(GenericLLM(name="g")).url == "http://127.0.0.1:8000"
    assert GenericHTTPClient(GenericLLM(name="g"), host="https://api.openai.com", port=None).url == "https://api.openai.com"
    assert GenericHTTPClient(GenericLLM(name="g"), host="http://gpu-box/openai", port=9000).url == "http://gpu-box:9000/openai"
    assert GenericHTTPClient(GenericLLM(name="g"), host="http://gpu-box:7000", port=9000).url == "http://gpu-box:7000"
    assert OllamaClient(OllamaModel(name="o"), host="10.0.0.5", port=None).url == "http://10.0.0.5:11434"
    ws = RoboMLWSClient(TransformersLLM(name="n"), host="gpu-box", port=8000)
    assert ws.websocket_url == "ws://gpu-box:8000/n/ws_inference"


def test_async_facade_does_not_block_the_event_loop(server):
    import asyncio

    from emos.actors.agents.clients import AsyncClient

    async def main() -> tuple[str, str, int]:
        client = AsyncClient(GenericHTTPClient(GenericLLM(name="llm", checkpoint="emos-scripted"), port=server.port))
        await client.check_connection()
        ticks = 0

        async def ticker() -> None:
            nonlocal ticks
            while True:
                ticks += 1
                await asyncio.sleep(0.001)

        task = asyncio.create_task(ticker())
        reply = await client.inference(ask("hello"))
        stream = await client.inference(ask("async stream works", stream=True))
        text = "".join([chunk.content async for chunk in stream])
        task.cancel()
        return reply.message.content, text, ticks

    reply, text, ticks = asyncio.run(main())
    assert reply == "Hello! I am a robot." and text == "You said: async stream works"
    assert ticks > 0  # the loop kept running while requests were in flight
