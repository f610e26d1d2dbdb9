"""The deterministic scripted responder behind the local model server."""
from __future__ import annotations

from pathlib import Path

import pytest

from emos.actors.agents.server.responder import ScriptedResponder, load_script
from emos.actors.agents.types import ChatMessage, ChatRequest, ToolSpec

pytestmark = pytest.mark.unit

SCRIPT = Path(__file__).parent / "fixtures" / "responder_script.yaml"
GO_TO = ToolSpec(name="go_to", parameters={"type": "object", "properties": {"place": {"type": "string"}}})


def req(*texts: str, **kw) -> ChatRequest:
    return ChatRequest(messages=[ChatMessage("user", t) for t in texts], **kw)


def test_rules_match_the_last_user_message_in_order():
    responder = ScriptedResponder(SCRIPT)
    assert responder.aliases == ["llama3.2:3b", "qwen2.5vl:latest"]
    assert responder.respond(req("hello"), "m").message.content == "Hello! I am a robot."
    assert responder.respond(req("hello", "What colour is the door?"), "m").message.content == "It is red."
    assert responder.respond(req("something else"), "m").message.content == "You said: something else"


def test_tool_rules_fill_regex_groups_and_need_the_tool_on_offer():
    responder = ScriptedResponder(SCRIPT)
    reply = responder.respond(req("Please go to the Garage now", tools=[GO_TO]), "m")
    assert reply.message.tool_calls[0].arguments == {"place": "Garage"} and reply.message.content is None
    ids = {responder.respond(req("go to the lab", tools=[GO_TO]), "m").message.tool_calls[0].id for _ in range(3)}
    assert len(ids) == 3  # every call gets its own id
    assert responder.respond(req("go to the lab"), "m").message.content == "You said: go to the lab"


def test_same_input_same_output():
    a, b = ScriptedResponder(SCRIPT), ScriptedResponder(SCRIPT)
    assert a.respond(req("tell me a story"), "m") == b.respond(req("tell me a story"), "m")


def test_stream_pieces_concatenate_to_the_reply():
    responder = ScriptedResponder({"rules": [], "default": "Line one.\n  Line two."})
    chunks = list(responder.stream(req("x"), "m"))
    assert "".join(c.content for c in chunks) == "Line one.\n  Line two."
    assert chunks[-1].done and not any(c.done for c in chunks[:-1])


def test_tool_results_are_reported_back():
    responder = ScriptedResponder()
    request = ChatRequest(messages=[ChatMessage("user", "go"), ChatMessage("tool", "42 degrees", name="thermometer")])
    assert responder.respond(request, "m").message.content == "Tool thermometer returned: 42 degrees"


@pytest.mark.parametrize(
    "script, message",
    [
        ({"rules": [{"reply": "x"}]}, "with 'match'"),
        ({"rules": [{"match": "(", "reply": "x"}]}, "bad regex"),
        ({"rules": [{"match": "a"}]}, "exactly one of 'reply' or 'tool_call'"),
        ({"rules": [{"match": "a", "tool_call": {"arguments": {}}}]}, "needs a 'name'"),
        ({"models": "llama"}, "'models' must be a list"),
        (["not", "a", "mapping"], "expected a mapping"),
    ],
)
def test_bad_scripts_are_rejected_with_the_reason(script, message):
    with pytest.raises(ValueError, match=message):
        load_script(script)


def test_script_files_can_be_json_and_must_exist(tmp_path):
    path = tmp_path / "s.json"
    path.write_text('{"rules": [{"match": "ping", "reply": "pong"}]}')
    assert ScriptedResponder(path).respond(req("ping"), "m").message.content == "pong"
    with pytest.raises(FileNotFoundError):
        load_script(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("rules: [unclosed")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_script(tmp_path / "bad.yaml")
