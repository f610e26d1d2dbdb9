"""RAG round trip: MapEncoding-style entries in the embedded Chroma, real embeddings, context
placed before the query."""
from __future__ import annotations

import json
import os

import pytest

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.db import ChromaClient, ChromaDB  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.logic.rag import RAGSettings, format_hits, retrieve, with_context  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.logic.templates import PromptBuilder  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import


@pytest.fixture()
def store(tmp_path):
    client = ChromaClient(ChromaDB(path=str(tmp_path / "rag")))
    client.add("map", ["yellow door", "kitchen with a fridge", "office desk with a computer"],
               metadatas=[{"coordinates": [1.1, 2.2, 0.0], "layer_name": "detections", "timestamp": 10.0,
                           "temporal_change": True},
                          {"coordinates": [5.0, -1.0, 0.0], "layer_name": "room", "timestamp": 11.0,
                           "temporal_change": False},
                          {"coordinates": [-3.0, 4.0, 0.0], "layer_name": "room", "timestamp": 12.0,
                           "temporal_change": False}], ids=["door", "kitchen", "office"])
    return client


def test_rag_round_trip_puts_context_with_metadata_before_the_query(store):
    settings = RAGSettings(enable_rag=True, collection_name="map", distance_func="l2", n_results=1, add_metadata=True)
    query = "Go to the yellow door"
    context = retrieve(store, settings, query)
    assert context.startswith("yellow door, ")
    metadata = json.loads(context[len("yellow door, "):])
    assert metadata["coordinates"] == [1.1, 2.2, 0.0] and metadata["layer_name"] == "detections"

    builder = PromptBuilder(["goto_in"])
    builder.set_component_prompt("From the given metadata, extract coordinates")
    prompt = with_context(context, builder.build({"goto_in": query}))
    assert prompt.index("yellow door") < prompt.index("From the given metadata")


def test_n_results_and_metadata_switch(store):
    settings = RAGSettings(enable_rag=True, collection_name="map", n_results=3)
    context = retrieve(store, settings, "where is the fridge?")
    lines = context.split("\n")
    assert len(lines) == 3 and lines[0] == "kitchen with a fridge"  # nearest first, no metadata
    assert "coordinates" not in context


def test_rag_off_or_empty_collection_leaves_the_prompt_alone(store):
    assert retrieve(store, RAGSettings(), "anything") == ""
    assert retrieve(store, RAGSettings(enable_rag=True, collection_name="nothing-here"), "x") == ""
    assert with_context("", "the prompt") == "the prompt"
    assert format_hits([], add_metadata=True) == ""


def test_rag_settings_validation():
    with pytest.raises(ValueError, match="collection_name"):
        RAGSettings(enable_rag=True)
    with pytest.raises(ValueError, match="n_results"):
        RAGSettings(n_results=0)
    with pytest.raises(ValueError, match="distance_func"):
        RAGSettings(distance_func="hamming")
