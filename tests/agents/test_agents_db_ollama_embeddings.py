"""ChromaDB with the Ollama embedding backend, against the local model server's real
``/api/embed`` endpoint (which serves the packaged all-MiniLM-L6-v2)."""
from __future__ import annotations

import socket

import numpy as np
import pytest

from emos.actors.agents.db import ChromaClient, ChromaDB
from emos.actors.agents.db.embedding import OllamaEmbedder
from emos.actors.agents.errors import ModelConnectionError, ModelServerError
from emos.actors.agents.local.embeddings import SentenceEmbedder

from .fixtures.server_process import start_server

pytestmark = pytest.mark.process


@pytest.fixture(scope="module")
def server():
    proc = start_server(script=None)
    yield proc
    assert proc.stop() == 143  # a clean SIGTERM exit


def test_ollama_backend_embeds_like_the_local_model_and_drives_queries(server, tmp_path):
    # The server loads its embedding model on the first request, as Ollama does: 6 s on an idle
    # machine, over a minute on a busy one. The timeout here only bounds a hang.
    db = ChromaDB(path=str(tmp_path / "s"), embeddings="ollama", checkpoint="all-minilm", ollama_port=server.port, request_timeout=300.0)
    client = ChromaClient(db)
    assert isinstance(client.embedder, OllamaEmbedder)
    texts = ["go to the kitchen", "what is the capital of France?"]
    remote = client.embed(texts)
    local = SentenceEmbedder().embed(texts)
    assert remote.shape == (2, 384) and np.allclose(remote, local, atol=1e-4)
    client.add("docs", ["a red fridge in the kitchen", "a desk in the office"], ids=["k", "o"])
    assert client.query("docs", "where is the fridge", n_results=1)[0].id == "k"


def test_ollama_backend_errors_are_typed(server):
    with pytest.raises(ModelServerError) as info:
        OllamaEmbedder("no-such-embedding-model", port=server.port).embed(["x"])
    assert 400 <= info.value.status < 500
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ModelConnectionError, match="cannot reach the Ollama server"):
        OllamaEmbedder("all-minilm", port=port).embed(["x"])
