"""ChromaClient against the real embedded store and a real ``chroma run`` server."""
from __future__ import annotations

import http.server
import os
import shutil
import socket
import subprocess
import threading
import time

import httpx
import numpy as np
import pytest

from emos.actors.agents.db import ChromaClient, ChromaDB
from emos.actors.agents.errors import MalformedResponseError, ModelConnectionError, ModelServerError

# ChromaClient.initialize loads the embedding model in this process: the module runs in the worker
# that loads it for the other embedding modules (tests/conftest.py). The timeout bounds a hang only:
# at load 50 the first load took over 300 s (6 s idle).
pytestmark = [pytest.mark.process, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

ROOMS = ["the kitchen has a red fridge and a stove",
         "the office has a desk, a chair and a computer",
         "the bedroom has a bed and a wardrobe"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def chroma_server(tmp_path_factory):
    exe = shutil.which("chroma")
    if exe is None:
        pytest.skip("the chromadb package installed here provides no `chroma` CLI")
    port = _free_port()
    path = tmp_path_factory.mktemp("chroma_server")
    proc = subprocess.Popen([exe, "run", "--path", str(path), "--port", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/v2/heartbeat", timeout=1).status_code == 200:
                break
        except httpx.TransportError:
            time.sleep(0.2)
    else:
        proc.kill()
        raise RuntimeError("chroma run did not start within 30 s")
    yield port
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()


@pytest.fixture(params=["embedded", "server"])
def client(request, tmp_path):
    if request.param == "embedded":
        db = ChromaDB(path=str(tmp_path / "store"))
    else:
        port = request.getfixturevalue("chroma_server")
        db = ChromaDB(host="127.0.0.1", port=port)
    c = ChromaClient(db)
    c.initialize()
    name = f"t{request.node.name.replace('[', '-').replace(']', '')}"[:60]
    c.reset(name)
    c.collection = name
    yield c
    c.reset(name)
    c.deinitialize()


def test_add_query_returns_nearest_with_metadata(client):
    ids = client.add(client.collection, ROOMS, metadatas=[{"room": "kitchen"}, {"room": "office"}, {"room": "bedroom"}],
                     ids=["k", "o", "b"])
    assert ids == ["k", "o", "b"]
    hits = client.query(client.collection, "where can I find the fridge?", n_results=2)
    assert [h.id for h in hits][0] == "k"
    assert len(hits) == 2 and hits[0].distance <= hits[1].distance
    assert hits[0].metadata == {"room": "kitchen"} and hits[0].document == ROOMS[0]


def test_query_many_keeps_one_list_per_query(client):
    client.add(client.collection, ROOMS, ids=["k", "o", "b"])
    results = client.query_many(client.collection, ["a bed to sleep", "a computer to work"], n_results=3)
    assert len(results) == 2
    assert all(len(hits) == 3 for hits in results)  # all n_results of each query, not one zipped hit
    assert results[0][0].id == "b" and results[1][0].id == "o"


def test_metadata_query_delete_and_upsert(client):
    client.add(client.collection, ROOMS, metadatas=[{"floor": 0}, {"floor": 1}, {"floor": 1}], ids=["k", "o", "b"])
    upstairs = client.metadata_query(client.collection, where={"floor": 1})
    assert sorted(r.id for r in upstairs) == ["b", "o"]
    client.delete(client.collection, where={"floor": 0})
    assert client.count(client.collection) == 2
    client.upsert(client.collection, ["the office is now a gym"], metadatas=[{"floor": 2}], ids=["o"])
    (record,) = client.metadata_query(client.collection, ids=["o"])
    assert record.document == "the office is now a gym" and record.metadata == {"floor": 2}
    client.delete(client.collection, ids=["o"])
    assert [r.id for r in client.metadata_query(client.collection)] == ["b"]


@pytest.mark.parametrize("space,expected", [
    ("l2", [0.0, 2.0]),        # Chroma's l2 is the squared Euclidean distance
    ("ip", [0.0, 1.0]),        # 1 - dot product
    ("cosine", [0.0, 1.0]),    # 1 - cosine similarity
])
def test_distance_functions_are_collection_spaces(client, space, expected):
    vectors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=np.float32)
    client.add(client.collection, ["x", "y"], ids=["x", "y"], distance_func=space, embeddings=vectors)
    (hits,) = client.query_many(client.collection, ["q"], n_results=2, distance_func=space,
                                embeddings=np.array([[1.0, 0.0, 0.0]]))
    assert [h.id for h in hits] == ["x", "y"]
    assert np.allclose([h.distance for h in hits], expected, atol=1e-4)
    other = "cosine" if space != "cosine" else "l2"
    with pytest.raises(ValueError, match="fixed when it is created"):
        client.query(client.collection, "x", distance_func=other)


def test_store_rejections_are_value_errors_on_both_backends(client):
    client.add(client.collection, ["a"], ids=["a"], embeddings=np.zeros((1, 3), np.float32))
    with pytest.raises(ValueError, match="dimension"):
        client.add(client.collection, ["b"], ids=["b"], embeddings=np.zeros((1, 4), np.float32))
    with pytest.raises(ValueError, match="Chroma rejected"):
        client.metadata_query(client.collection, where={"k": {"$near": 1}})


def test_reset_empties_and_missing_collections_read_empty(client):
    client.add(client.collection, ROOMS)
    client.reset(client.collection)
    assert client.count(client.collection) == 0
    assert client.query(client.collection, "fridge") == []
    assert client.metadata_query(client.collection, where={"room": "x"}) == []


def test_bad_inputs_raise_clear_errors(tmp_path):
    client = ChromaClient(ChromaDB(path=str(tmp_path / "s")))
    with pytest.raises(ValueError, match="collection name"):
        client.add("x", ["doc"])
    with pytest.raises(ValueError, match="distance"):
        client.add("docs", ["doc"], distance_func="manhattan", embeddings=np.zeros((1, 3)))
    with pytest.raises(ValueError, match="distinct ids"):
        client.add("docs", ["a", "b"], ids=["1", "1"], embeddings=np.zeros((2, 3)))
    with pytest.raises(TypeError, match="one str"):
        client.add("docs", "a single string")
    with pytest.raises(ValueError, match="n_results"):
        client.query("docs", "q", n_results=0)
    with pytest.raises(ValueError, match="give ids or a where"):
        client.delete("docs")


def test_spec_validation():
    with pytest.raises(ValueError, match="embeddings"):
        ChromaDB(embeddings="word2vec")
    with pytest.raises(ValueError, match="port"):
        ChromaDB(host="127.0.0.1", port=70000)
    assert not ChromaDB().is_server and ChromaDB(host="h").server_url == "http://h:8000/api/v2"
    assert ChromaDB(embeddings="ollama").embedding_checkpoint == "nomic-embed-text"


def test_refused_connection_is_typed():
    client = ChromaClient(ChromaDB(host="127.0.0.1", port=_free_port(), request_timeout=2.0))
    with pytest.raises(ModelConnectionError, match="cannot reach the Chroma server"):
        client.check_connection()


class _Garbage(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - http.server API
        status = 500 if self.path.endswith("/version") else 200
        body = b"<html>not json</html>"
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


def test_garbage_and_failing_servers_are_typed():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Garbage)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        db = ChromaDB(host="127.0.0.1", port=server.server_address[1])
        with pytest.raises(MalformedResponseError):
            ChromaClient(db).check_connection()
        from emos.actors.agents.db.backends import HTTPBackend
        with pytest.raises(ModelServerError) as info:
            HTTPBackend(db)._call("GET", "/version")
        assert info.value.status == 500
    finally:
        server.shutdown()
        server.server_close()


def test_client_rebuilds_from_its_serialized_form_in_another_process(tmp_path):
    import json
    import pickle
    import sys

    client = ChromaClient(ChromaDB(path=str(tmp_path / "shared")))
    client.add("shared-docs", ["hello"], ids=["h"], embeddings=np.ones((1, 3), np.float32))
    client.deinitialize()
    data = json.dumps(client.serialize())
    code = ("import json, sys\nfrom emos.actors.agents.db import ChromaClient\n"
            "c = ChromaClient.from_serialized(json.loads(sys.argv[1]))\n"
            "print([r.id for r in c.metadata_query('shared-docs')])")
    out = subprocess.run([sys.executable, "-c", code, data], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "['h']"
    clone = pickle.loads(pickle.dumps(client))
    assert clone.db == client.db and clone._backend is None
    with pytest.raises(ValueError, match="serialized ChromaClient"):
        ChromaClient.from_serialized({"db": {}})
