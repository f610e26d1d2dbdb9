"""Wire formats checked against fixtures written from the OpenAI and Ollama API references
(see fixtures/SOURCES.md): request bodies we build, responses and streams we parse."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from emos.actors.agents.clients import ollama_codec, openai_codec
from emos.actors.agents.clients.sse import format_sse, iter_sse_data
from emos.actors.agents.errors import MalformedResponseError
from emos.actors.agents.types import ChatMessage, ChatRequest, ImageData, ToolSpec

pytestmark = pytest.mark.unit

FIXTURES = Path(__file__).parent / "fixtures"
CTX = {"client": "test", "model": "m", "url": "http://fixture"}


def load(name: str):
    return json.loads((FIXTURES / name).read_text())


def lines(name: str):
    return (FIXTURES / name).read_text().splitlines()


@pytest.fixture(scope="module")
def red_pixel() -> ImageData:
    return ImageData.from_base64((FIXTURES / "red_pixel.png.b64").read_text().strip())


def go_to_tool() -> ToolSpec:
    return ToolSpec(name="go_to", description="Drive to a named place",
                    parameters={"type": "object", "properties": {"place": {"type": "string"}}, "required": ["place"]})


def vision_request(red_pixel: ImageData) -> ChatRequest:
    return ChatRequest(
        messages=[ChatMessage("system", "You are a robot."),
                  ChatMessage("user", "What colour is this? Then go there.", images=[red_pixel.data])],
        tools=[go_to_tool()], temperature=0.2, max_tokens=64,
    )


# ------------------------------------------------------------------ OpenAI


def test_openai_request_body_matches_the_reference_shape(red_pixel):
    assert red_pixel.mime_type == "image/png"
    payload = openai_codec.build_chat_payload(vision_request(red_pixel), "gpt-4o")
    assert payload == load("openai_chat_request.json")


def test_openai_model_options_are_defaults_that_the_request_overrides(red_pixel):
    payload = openai_codec.build_chat_payload(vision_request(red_pixel), "gpt-4o", {"temperature": 0.9, "top_p": 0.5})
    assert payload["temperature"] == 0.2 and payload["top_p"] == 0.5


def test_openai_tool_call_arguments_are_decoded_from_json_strings():
    response = openai_codec.parse_chat_response(load("openai_chat_response_tool_calls.json"), CTX)
    assert response.message.content is None and response.finish_reason == "tool_calls"
    assert [(c.id, c.name, c.arguments) for c in response.message.tool_calls] == [
        ("call_1", "go_to", {"place": "kitchen"}), ("call_2", "say", {"text": "On my way", "volume": 0.5})]
    assert response.usage["total_tokens"] == 99 and response.model == "gpt-4o-2024-08-06"
    # The assistant turn goes back to the model with arguments re-encoded as a JSON string.
    echoed = openai_codec.message_to_openai(response.message)
    assert json.loads(echoed["tool_calls"][0]["function"]["arguments"]) == {"place": "kitchen"}


def test_openai_truncated_tool_arguments_are_a_malformed_response():
    with pytest.raises(MalformedResponseError, match="tool-call arguments") as info:
        openai_codec.parse_chat_response(load("openai_chat_response_bad_arguments.json"), CTX)
    assert "http://fixture" in str(info.value)


def test_openai_text_stream_with_null_delta_and_usage_chunk():
    chunks = list(openai_codec.parse_chat_stream(iter_sse_data(lines("openai_chat_stream_text.sse")), CTX))
    assert "".join(c.content for c in chunks) == "Hello there!"
    assert all(not c.done for c in chunks[:-1]) and chunks[-1].done
    assert chunks[-1].finish_reason == "stop" and chunks[-1].usage["total_tokens"] == 12
    assert chunks[-1].tool_calls == []


def test_openai_streamed_tool_calls_are_assembled_from_fragments():
    chunks = list(openai_codec.parse_chat_stream(iter_sse_data(lines("openai_chat_stream_tool_calls.sse")), CTX))
    assert [c.content for c in chunks[:-1]] == []
    final = chunks[-1]
    assert final.done and final.finish_reason == "tool_calls"
    assert [(c.id, c.name, c.arguments) for c in final.tool_calls] == [
        ("call_abc", "go_to", {"place": "kitchen"}), ("call_def", "stop", {})]


def test_openai_stream_cut_off_before_done_is_malformed():
    stream = openai_codec.parse_chat_stream(iter_sse_data(lines("openai_chat_stream_truncated.sse")), CTX)
    with pytest.raises(MalformedResponseError, match=r"\[DONE\]"):
        list(stream)


def test_openai_stream_with_garbage_data_is_malformed():
    with pytest.raises(MalformedResponseError, match="SSE data line"):
        list(openai_codec.parse_chat_stream(iter(["{not json"]), CTX))


def test_sse_parser_handles_comments_multiline_data_and_crlf():
    raw = [": keep-alive", "event: message", "data: {\"a\":", "data: 1}", "", "data: [DONE]\r", ""]
    assert list(iter_sse_data(raw)) == ['{"a":\n1}', "[DONE]"]
    assert list(iter_sse_data(format_sse('{"x": 1}').decode().splitlines())) == ['{"x": 1}']


def test_openai_server_side_round_trip(red_pixel):
    model, request = openai_codec.chat_request_from_openai(load("openai_chat_request.json"))
    assert model == "gpt-4o"
    assert request.messages[1].images[0] == red_pixel and request.messages[1].content.startswith("What colour")
    assert request.tools[0].name == "go_to" and request.max_tokens == 64
    assert openai_codec.build_chat_payload(request, model) == load("openai_chat_request.json")


# ------------------------------------------------------------------ Ollama


def test_ollama_request_body_matches_the_reference_shape(red_pixel):
    request = vision_request(red_pixel)
    request.options = {"num_ctx": 4096}
    payload = ollama_codec.build_chat_payload(request, "qwen2.5vl:latest", {"temperature": 0.7}, keep_alive="5m")
    assert payload == load("ollama_chat_request.json")
    assert payload["messages"][1]["images"][0] == red_pixel.to_base64()  # bare base64, no data URL


def test_ollama_tool_calls_with_object_arguments():
    response = ollama_codec.parse_chat_response(load("ollama_chat_response_tool_calls.json"), CTX)
    call = response.message.tool_calls[0]
    assert (call.name, call.arguments) == ("go_to", {"place": "kitchen"})
    assert response.finish_reason == "tool_calls"
    assert response.usage == {"prompt_tokens": 155, "completion_tokens": 81, "total_tokens": 236}


def ndjson(name: str):
    return (json.loads(line) for line in lines(name) if line.strip())


def test_ollama_stream_ends_at_done():
    chunks = list(ollama_codec.parse_chat_stream(ndjson("ollama_chat_stream.ndjson"), CTX))
    assert "".join(c.content for c in chunks) == "The sky is blue."
    assert chunks[-1].done and chunks[-1].finish_reason == "stop" and chunks[-1].usage["completion_tokens"] == 282


def test_ollama_streamed_tool_calls_arrive_on_the_done_chunk():
    chunks = list(ollama_codec.parse_chat_stream(ndjson("ollama_chat_stream_tool_calls.ndjson"), CTX))
    assert len(chunks) == 1 and chunks[0].done
    assert chunks[0].tool_calls[0].arguments == {"place": "kitchen"} and chunks[0].finish_reason == "tool_calls"


def test_ollama_stream_without_done_is_malformed():
    with pytest.raises(MalformedResponseError, match="'done': true"):
        list(ollama_codec.parse_chat_stream(ndjson("ollama_chat_stream_truncated.ndjson"), CTX))


def test_ollama_server_side_round_trip(red_pixel):
    model, request = ollama_codec.chat_request_from_ollama(load("ollama_chat_request.json"))
    assert model == "qwen2.5vl:latest" and request.temperature == 0.2 and request.max_tokens == 64
    assert request.options == {"num_ctx": 4096} and request.messages[1].images == [red_pixel]
    assert request.stream is False


def test_embedding_rows_are_ordered_by_index():
    from emos.actors.agents.types import EmbeddingResponse

    body = load("openai_embeddings_response.json")
    rows = sorted(body["data"], key=lambda d: d["index"])
    response = EmbeddingResponse(embeddings=[r["embedding"] for r in rows])
    assert np.allclose(response.embeddings, [[0.6, 0.0, 0.8], [0.0, 1.0, 0.0]])
    ollama = EmbeddingResponse(embeddings=load("ollama_embed_response.json")["embeddings"])
    assert ollama.embeddings.shape == (2, 3) and ollama.embeddings.dtype == np.float32
