"""Issue 33 D6 (the router part): a default-route decision says why in the words of the mode that
made it. The LLM-mode router logged "nearest None at None": there is no nearest sample when a
model decides, only the tool calls it made."""
from __future__ import annotations

import os

import pytest

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.db import ChromaClient, ChromaDB  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.logic.router import LLMRouter, Route, SemanticRouterConfig, VectorRouter  # noqa: E402
from emos.actors.agents.types import ChatMessage, ChatResponse, ToolCall  # noqa: E402

GOTO = Route(routes_to="goto_in", samples=["Go to the door", "Go to the kitchen"])
LLM = Route(routes_to="text_in_llm", samples=["What is the capital of France?", "How are you today?"])


def _model_answering(*tool_names: str):
    """A chat function that answers with these tool calls (the model's side of LLM mode)."""
    def chat(request):
        calls = [ToolCall(id=str(i), name=name) for i, name in enumerate(tool_names)]
        return ChatResponse(message=ChatMessage(role="assistant", content="hm", tool_calls=calls))
    return chat


def test_llm_mode_default_route_names_what_the_model_did():
    decision = LLMRouter([LLM, GOTO], _model_answering(), default_route=LLM).decide("hello there")
    assert decision.is_default and decision.route is LLM
    assert decision.reason == "the model called no route tool"
    assert "None" not in decision.reason
    decision = LLMRouter([LLM, GOTO], _model_answering("x" * 500, "make_coffee"), default_route=LLM).decide("hi")
    assert decision.is_default
    assert decision.reason == f"the model called no route tool (it called {'x' * 64!r}, 'make_coffee')"
    decision = LLMRouter([LLM, GOTO], _model_answering("route_to_goto_in"), default_route=LLM).decide("go to the door")
    assert decision.route is GOTO and not decision.is_default and decision.reason == ""


def test_vector_mode_default_route_names_the_nearest_sample_and_its_distance(tmp_path):
    router = VectorRouter([LLM, GOTO], ChromaClient(ChromaDB(path=str(tmp_path / "db"))),
                          SemanticRouterConfig(router_name="reasons", maximum_distance=0.3), default_route=LLM)
    router.initialize()
    decision = router.decide("The mitochondria is the powerhouse of the cell")
    assert decision.is_default and decision.distance > 0.3
    assert decision.reason.startswith(f"no route close enough (nearest sample {decision.matched_sample!r} at l2 distance ")
    assert decision.reason.endswith(" > 0.3)")
