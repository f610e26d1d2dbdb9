"""MapEncoding storage: binned ids, temporal entries, pre-defined points and metadata, in the
real embedded Chroma store with real embeddings."""
from __future__ import annotations

import os

import numpy as np
import pytest

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.db import ChromaClient, ChromaDB  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.logic.map_encoding import MapConfig, MapEncoder, MapLayer  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import


@pytest.fixture()
def client(tmp_path):
    return ChromaClient(ChromaDB(path=str(tmp_path / "map")))


def _encoder(client) -> MapEncoder:
    layer1 = MapLayer(subscribes_to="detections", temporal_change=True)
    layer2 = MapLayer(subscribes_to="introspection_answer", resolution_multiple=3,
                      pre_defined=[(np.array([4.0, 4.0]), "charging dock")])
    return MapEncoder([layer1, layer2], client, MapConfig(map_name="map"), resolution=0.05)


def test_non_temporal_layer_keeps_one_entry_per_binned_cell(client):
    encoder = _encoder(client)
    # resolution 0.05 * multiple 3 = 0.15 m cells: both positions fall in cell (6, 13)
    first = encoder.encode("introspection_answer", "kitchen", [1.01, 2.02], timestamp=100.0)
    second = encoder.encode("introspection_answer", "office", [1.04, 2.08, 0.0], timestamp=105.0)
    assert first == second == "introspection_answer:6:13"
    (record,) = client.metadata_query("map", where={"layer_name": "introspection_answer"})
    assert record.document == "office"
    assert record.metadata == {"coordinates": [0.975, 2.025, 0.0], "layer_name": "introspection_answer",
                               "timestamp": 105.0, "temporal_change": False}
    third = encoder.encode("introspection_answer", "bedroom", [1.2, 2.02], timestamp=106.0)
    assert third == "introspection_answer:8:13"  # the next cell over


def test_temporal_layer_keeps_every_observation_with_its_timestamp(client):
    encoder = _encoder(client)
    ids = [encoder.encode("detections", text, [1.01, 2.02, 0.0], timestamp=t)
           for text, t in (("person, chair", 100.0), ("chair", 160.5))]
    assert ids == ["detections:20:40:100000000", "detections:20:40:160500000"]
    records = sorted(client.metadata_query("map", where={"temporal_change": True}),
                     key=lambda r: r.metadata["timestamp"])
    assert [r.document for r in records] == ["person, chair", "chair"]
    assert all(r.metadata["coordinates"] == [1.025, 2.025, 0.0] for r in records)


def test_pre_defined_points_and_retrieval_by_meaning(client):
    encoder = _encoder(client)
    assert encoder.add_pre_defined(timestamp=1.0) == ["introspection_answer:pre_defined:0"]
    assert encoder.add_pre_defined(timestamp=2.0) == ["introspection_answer:pre_defined:0"]  # idempotent
    encoder.encode("detections", "a yellow door", [7.3, -2.2], timestamp=3.0)
    (hit,) = client.query("map", "where can the robot recharge its battery?", n_results=1)
    assert hit.document == "charging dock"
    assert hit.metadata["coordinates"] == [3.975, 3.975, 0.0] and hit.metadata["timestamp"] == 2.0


def test_empty_texts_are_skipped_and_batches_keep_the_last_observation(client):
    encoder = _encoder(client)
    assert encoder.encode("detections", "   ", [0, 0]) is None
    ids = encoder.encode_many("introspection_answer", ["kitchen", "office", ""], [[0, 0], [0.01, 0.01], [5, 5]],
                              timestamps=[1.0, 2.0, 3.0])
    assert ids == ["introspection_answer:0:0"]
    (record,) = client.metadata_query("map")
    assert record.document == "office"


def test_bad_inputs_fail_clearly(client):
    encoder = _encoder(client)
    with pytest.raises(KeyError, match="unknown map layer"):
        encoder.encode("lidar", "x", [0, 0])
    with pytest.raises(ValueError, match="position"):
        encoder.encode("detections", "x", [0, float("nan")])
    with pytest.raises(ValueError, match="resolution_multiple"):
        MapLayer(subscribes_to="x", resolution_multiple=0)
    with pytest.raises(ValueError, match="pre_defined"):
        MapLayer(subscribes_to="x", pre_defined=[([0, 0], "")])
    with pytest.raises(RuntimeError, match="resolution unknown"):
        MapEncoder([MapLayer(subscribes_to="x")], client).encode("x", "text", [0, 0])
    with pytest.raises(ValueError, match="one layer only"):
        MapEncoder([MapLayer(subscribes_to="x"), MapLayer(subscribes_to="x")], client)
