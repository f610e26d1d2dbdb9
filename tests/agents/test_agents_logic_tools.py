"""Tool calling both ways and LLM-mode routing, against the local model server over real HTTP."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from emos.actors.agents.clients import GenericHTTPClient
from emos.actors.agents.logic.router import LLMRouter, Route
from emos.actors.agents.logic.streaming import chunk_stream
from emos.actors.agents.logic.tools import (
    ToolArgumentError,
    ToolError,
    ToolRegistry,
    normalize_schema,
    run_tool_loop,
)
from emos.actors.agents.models import GenericLLM
from emos.actors.agents.types import ChatMessage, ChatRequest, ToolCall

from .fixtures.server_process import start_server

pytestmark = pytest.mark.process

SCRIPT = Path(__file__).parent / "data" / "logic_responder_script.yaml"

# The tool-calling recipe's description, verbatim in structure: "list[float]" type and
# "required" placed beside "parameters".
GET_COORDINATES = {
    "type": "function",
    "function": {
        "name": "get_coordinates",
        "description": "Get position coordinates",
        "parameters": {"type": "object", "properties": {
            "position": {"type": "list[float]", "description": "The position coordinates in x, y and z"}}},
        "required": ["position"],
    },
}
ADD = {"type": "function", "function": {
    "name": "add", "description": "Add two integers",
    "parameters": {"type": "object", "properties": {"a": {"type": "integer"}, "b": {"type": "integer"}},
                   "required": ["a", "b"]}}}


def get_coordinates(position: list[float]) -> np.ndarray:
    return np.array(position, dtype=float)


def add(a: int, b: int) -> int:
    return a + b


@pytest.fixture(scope="module")
def chat():
    server = start_server(script=str(SCRIPT))
    client = GenericHTTPClient(GenericLLM(name="llm", checkpoint="emos-scripted"), port=server.port)
    client.initialize()
    yield client.inference
    client.deinitialize()
    assert server.stop() == 143  # a clean SIGTERM exit


def ask(text: str) -> ChatRequest:
    return ChatRequest(messages=[ChatMessage("system", "You are a robot."), ChatMessage("user", text)])


def test_tool_output_is_published_directly_when_not_sent_back(chat):
    registry = ToolRegistry()
    registry.register_tool(get_coordinates, GET_COORDINATES, send_tool_response_to_model=False)
    result = run_tool_loop(chat, ask("What are the position coordinates in the given metadata?"), registry)
    assert isinstance(result.output, np.ndarray)
    assert result.output.tolist() == [1.0, 2.5, 0.0]
    assert result.text is None


def test_tool_result_goes_back_to_the_model_when_asked(chat):
    registry = ToolRegistry()
    # the script sends "a" and "b" as strings; the schema wants integers, so the first round's
    # validation error goes back to the model as the tool message.
    registry.register_tool(add, ADD, send_tool_response_to_model=True)
    result = run_tool_loop(chat, ask("what is 2 plus 3"), registry)
    assert result.output.startswith("Tool add returned: error:") and "is not of type 'integer'" in result.output
    assert [m.role for m in result.messages] == ["assistant", "tool", "assistant"]

    registry = ToolRegistry()
    registry.register_tool(lambda a, b: int(a) + int(b), {"type": "function", "function": {
        "name": "add", "parameters": {"type": "object", "properties": {"a": {"type": "string"},
                                                                       "b": {"type": "string"}}}}},
                           send_tool_response_to_model=True)
    result = run_tool_loop(chat, ask("what is 2 plus 3"), registry)
    assert result.output == "Tool add returned: 5"
    tool_message = result.messages[1]
    assert tool_message.role == "tool" and tool_message.tool_call_id == result.messages[0].tool_calls[0].id


def test_no_tool_call_returns_the_model_text(chat):
    registry = ToolRegistry()
    registry.register_tool(add, ADD, send_tool_response_to_model=True)
    assert run_tool_loop(chat, ask("sing me a song"), registry).output == "I do not know"


def test_argument_validation_and_registration_errors():
    registry = ToolRegistry()
    registry.register_tool(get_coordinates, GET_COORDINATES)
    with pytest.raises(ToolArgumentError, match="'position' is a required property"):
        registry.call(ToolCall(id="1", name="get_coordinates", arguments={}))
    with pytest.raises(ToolArgumentError, match="position/1: 'y' is not of type 'number'"):
        registry.call(ToolCall(id="1", name="get_coordinates", arguments={"position": [1, "y"]}))
    with pytest.raises(ToolError, match="unknown tool 'fly'"):
        registry.call(ToolCall(id="1", name="fly", arguments={}))
    with pytest.raises(ValueError, match="not arguments of"):
        registry.register_tool(lambda x: x, ADD)
    with pytest.raises(ValueError, match="unknown parameter type"):
        registry.register_tool(add, {"function": {"name": "add", "parameters": {
            "type": "object", "properties": {"a": {"type": "quaternion"}}}}})
    assert normalize_schema({"type": "list[list[int]]"}) == {
        "type": "array", "items": {"type": "array", "items": {"type": "integer"}}}


def test_direct_tool_with_bad_arguments_raises(chat):
    registry = ToolRegistry()
    registry.register_tool(add, ADD, send_tool_response_to_model=False)
    with pytest.raises(ToolArgumentError, match="is not of type 'integer'"):
        run_tool_loop(chat, ask("what is 2 plus 3"), registry)


def test_llm_router_decides_from_the_tool_call(chat):
    goto = Route(routes_to="goto_in", samples=["Go to the door", "Fetch a ball"])
    llm = Route(routes_to="llm_in", samples=["What is the capital of France?"])
    mllm = Route(routes_to="mllm_in", samples=["What do you see?"])
    router = LLMRouter([llm, goto, mllm], chat, default_route=llm)
    assert {t.name for t in router.tools} == {"route_to_goto_in", "route_to_llm_in", "route_to_mllm_in"}
    assert router.decide("Go to the kitchen").route is goto
    assert router.decide("Do you see any people?").route is mllm
    assert router.decide("Who wrote Hamlet?").route is llm
    decision = router.decide("banana")  # the model answers without calling a tool
    assert decision.route is llm and decision.is_default


def test_streamed_reply_is_chunked_by_sentence(chat):
    request = ChatRequest(messages=[ChatMessage("user", "tell me about yourself")], stream=True)
    chunks = list(chat(request))
    assert len(chunks) > 3  # streamed word by word, ending with an empty "done" chunk
    assert list(chunk_stream(chunks, ".")) == ["I am a robot.", "I can drive to places.", "I like kitchens"]
