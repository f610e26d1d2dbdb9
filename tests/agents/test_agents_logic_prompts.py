"""Prompt templates, chat history, stream chunking, preprocessor chains, detections as text."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.agents.local.vision import Detection
from emos.actors.agents.logic.detections import detections_to_text
from emos.actors.agents.logic.history import ChatHistory
from emos.actors.agents.logic.preprocess import PreprocessorChain
from emos.actors.agents.logic.streaming import StreamChunker, chunk_stream
from emos.actors.agents.logic.templates import PromptBuilder, PromptTemplate, TemplateVariableError
from emos.actors.agents.types import ChatChunk, ChatMessage, ImageData, ToolCall

pytestmark = pytest.mark.unit


# ----------------------------------------------------------------- templates
def test_topic_and_component_templates_compose_the_prompt():
    builder = PromptBuilder(["text0", "detections"])
    builder.set_topic_prompt("text0", "Question: {{ text0 }}")
    assert builder.build({"text0": "what is red?", "detections": "cup"}) == "Question: what is red?\ncup"
    builder.set_component_prompt("Imagine you are a robot.\nThis image has following items: {{ detections }}.\n"
                                 "Answer the following about this image: {{ text0 }}")
    prompt = builder.build({"text0": "what is red?", "detections": "cup x2, person"})
    assert prompt == ("Imagine you are a robot.\nThis image has following items: cup x2, person.\n"
                      "Answer the following about this image: Question: what is red?")


def test_templates_from_files(tmp_path):
    path = tmp_path / "prompt.jinja"
    path.write_text("You are an amazing and funny robot.\nAnswer: {{ text0 }}")
    assert PromptTemplate(path).render({"text0": "hi"}).endswith("Answer: hi")
    assert PromptTemplate(str(path)).variables == {"text0"}
    with pytest.raises(FileNotFoundError, match="does not exist"):
        PromptTemplate(tmp_path / "missing.jinja")


def test_missing_variables_are_named_at_definition_and_render_time():
    builder = PromptBuilder(["text0"])
    with pytest.raises(TemplateVariableError, match=r"\['text1'\]"):
        builder.set_component_prompt("Answer {{ text1 }}")
    with pytest.raises(ValueError, match="not an input topic"):
        builder.set_topic_prompt("image0", "{{ image0 }}")
    with pytest.raises(TemplateVariableError, match=r"needs \['place'\]"):
        PromptTemplate("Go to {{ place }} now").render({"other": "x"})
    with pytest.raises(ValueError, match="syntax error"):
        PromptTemplate("Broken {{ text0 ")
    # a component prompt without any topic variable is allowed (RAG-only Go-to-X prompt)
    builder.set_component_prompt("What are the position coordinates in the given metadata?")
    assert builder.build({"text0": "go to the door"}) == "What are the position coordinates in the given metadata?"


# ----------------------------------------------------------------- history
def _turn(i: int) -> list[ChatMessage]:
    return [ChatMessage("user", f"question {i}"), ChatMessage("assistant", f"answer {i}")]


def test_history_keeps_the_last_messages_and_the_system_prompt():
    history = ChatHistory(history_size=4, system_prompt="You are a robot.")
    for i in range(5):
        history.add(*_turn(i))
    messages = history.messages(ChatMessage("user", "question 5"))
    assert [m.content for m in messages] == ["You are a robot.", "question 3", "answer 3", "question 4",
                                             "answer 4", "question 5"]


def test_reset_phrase_clears_turns_but_keeps_the_system_prompt():
    history = ChatHistory(system_prompt="You are a robot.")
    history.add(*_turn(0))
    assert history.is_reset("Chat reset.") and not history.is_reset("please chat reset the thing")
    history.reset()
    assert len(history) == 0
    assert [m.role for m in history.messages()] == ["system"]


def test_history_strips_images_and_never_starts_inside_a_tool_exchange():
    png = ImageData.from_array(np.zeros((2, 2, 3), np.uint8))
    history = ChatHistory(history_size=3)
    history.add(ChatMessage("user", "what is this?", images=[png]), ChatMessage("assistant", "a black square"))
    assert all(not m.images for m in history.messages())
    call = ToolCall(id="c1", name="add", arguments={"a": 1})
    history.add(ChatMessage("user", "add"), ChatMessage("assistant", None, tool_calls=[call]),
                ChatMessage("tool", "2", tool_call_id="c1"), ChatMessage("assistant", "It is 2"))
    assert [m.role for m in history.messages()] == ["assistant", "tool", "assistant"]
    history.add(ChatMessage("user", "again"))  # the window moves: the orphan tool result goes too
    assert [m.role for m in history.messages()] == ["assistant", "user"]
    with pytest.raises(ValueError, match="history_size"):
        ChatHistory(history_size=1)


# ----------------------------------------------------------------- streaming
def test_stream_chunker_splits_on_break_character_and_tolerates_null_chunks():
    chunks = [ChatChunk(content="Hello the"), ChatChunk(content=None), ChatChunk(content="re. I am a"),
              ChatChunk(content=" robot. Bye"), None, "!"]
    assert list(chunk_stream(chunks, ".")) == ["Hello there.", "I am a robot.", "Bye!"]
    chunker = StreamChunker("\n")
    assert chunker.feed("line one\nline") == ["line one"]
    assert chunker.feed(" two\n\n") == ["line two"]
    assert chunker.flush() == []
    assert StreamChunker("").feed("as is") == ["as is"]


# ----------------------------------------------------------------- preprocessors
def test_preprocessor_chain_runs_in_order_and_none_publishes_nothing():
    def pick_room(output: str):
        for option in ["office", "bedroom", "kitchen"]:
            if option in output.lower():
                return option
        return None

    chain = PreprocessorChain("introspection_answer")
    chain.add(pick_room)
    chain.add(str.upper)
    assert chain("I think this is a Kitchen.") == "KITCHEN"
    assert chain("No idea") is None
    with pytest.raises(TypeError, match="one positional argument"):
        chain.add(lambda a, b: a)
    with pytest.raises(TypeError, match="callable"):
        chain.add("not callable")


# ----------------------------------------------------------------- detections
def test_detections_to_text():
    dets = [Detection("person", 0.9, (10, 20, 50, 120)), Detection("chair", 0.7, (0, 0, 5, 5)),
            {"label": "person", "score": 0.3, "box": (1, 2, 3, 4)}]
    assert detections_to_text(dets) == "person x2, chair"
    assert detections_to_text(dets, min_score=0.5) == "person, chair"
    assert detections_to_text(dets[:1], with_boxes=True, with_scores=True) == "person (0.90) at [10, 20, 50, 120]"
    assert detections_to_text([]) == "nothing"
    with pytest.raises(ValueError, match="label"):
        detections_to_text([{"score": 1.0}])
