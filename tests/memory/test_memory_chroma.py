"""The memory's semantic part on real Chroma with the packaged all-MiniLM-L6-v2 (loading it
takes 10-60 s on this machine: a process-tier test)."""
from __future__ import annotations

import pytest

from emos.actors.agents.memory import MemoryStore
from tests.memory.test_memory_store import Clock, _walk

# Its ChromaClient loads the embedding model in the test process: one worker does (tests/conftest.py).
pytestmark = [pytest.mark.process, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]


@pytest.fixture(scope="module")
def chroma(tmp_path_factory):
    from emos.actors.agents import ChromaClient, ChromaDB

    client = ChromaClient(db=ChromaDB(path=str(tmp_path_factory.mktemp("chroma"))))
    client.initialize()
    yield client
    client.deinitialize()


def test_semantic_search_and_recall_through_real_chroma(chroma):
    clock = Clock()
    store = MemoryStore(vector=chroma, collection="memory_test", clock=clock)
    _walk(store, clock)
    hits = store.semantic_search("someone wants a drink", n_results=1)
    assert hits and "glass of water" in hits[0]["text"]
    hits = store.semantic_search("a couch", n_results=1)
    assert hits[0]["labels"] == ["person", "sofa"]
    recalled = store.recall("the cup")
    assert recalled["last_seen"]["found"] and recalled["memories"]
    # consolidation replaces the vectors of folded records by the episode's
    before = chroma.count("memory_test")
    folded = store.consolidate()
    assert folded >= 1 and chroma.count("memory_test") == before - folded + (len(store._records) - (before - folded))
