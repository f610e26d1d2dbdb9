"""Issue 33 D9: the semantic-map recipe's first map write blocked about 85 s, so one entry landed
in 100 s. py-spy showed the write importing sentence-transformers and torch (19 of the 21.6 s the
worker ran in our measurement): the embedding model loaded on the first write, and every trigger
that came while it loaded was skipped. Now the model loads at activation and each trigger's
observations are queued, not skipped: one entry per trigger and new message, however long a write
takes. Counted per input message on the component's simulated clock, not against wall time."""
from __future__ import annotations

import os

import numpy as np
import pytest

from emos import msgs as M
from emos.io.topic import Topic
from emos.testing import ComponentHarness
from tests.runtime.helpers import HANG_S

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents import ChromaClient, ChromaDB, MapConfig, MapEncoding, MapLayer  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import


def _odom(x: float) -> M.Odometry:
    odom = M.Odometry()
    odom.pose.pose.position.x = x
    return odom


def test_every_trigger_with_a_new_detection_writes_one_entry_even_while_the_model_loads(tmp_path):
    detections = Topic(name="detections", msg_type="Detections")
    mapper = MapEncoding(layers=[MapLayer(subscribes_to=detections, temporal_change=True)],
                         position=Topic(name="odom", msg_type="Odometry"),
                         map_topic=Topic(name="map", msg_type="OccupancyGrid"),
                         config=MapConfig(map_name="map"),
                         db_client=ChromaClient(db=ChromaDB(path=str(tmp_path / "chroma"))),  # the spec's ChromaDB()
                         trigger=15.0, component_name="map_encoding")
    with ComponentHarness(mapper) as h:
        h.feed("/map", M.OccupancyGrid(info=M.MapMetaData(resolution=0.5, width=20, height=20), data=np.zeros(400, np.int8)))
        # At once, as in the recipe: the first triggers come while the model may still load.
        for i in range(6):
            h.feed("/odom", _odom(float(i)))
            h.feed("/detections", M.Detections(labels=[f"thing{i}"], scores=np.ones(1), boxes=np.zeros((1, 4))))
            h.advance(15.0)  # one trigger per 15 s of the component's clock
        h.wait_for(lambda: not mapper._worker.busy, timeout=3 * HANG_S, what="the queued map writes")
        assert h.health.is_healthy, h.health.message
        assert mapper.entries_written == 6, f"{mapper.entries_written} entries for 6 triggers with a new detection each"
        assert mapper.dropped_observations == 0
        records = mapper.db_client.metadata_query("map")
    stamps = sorted(r.metadata["timestamp"] for r in records)
    assert stamps == [15.0, 30.0, 45.0, 60.0, 75.0, 90.0]  # each observed at its own trigger, on the clock
    assert sorted(r.document for r in records) == [f"thing{i}" for i in range(6)]


def test_a_store_that_cannot_be_opened_drops_observations_with_a_word(tmp_path, caplog):
    bad = tmp_path / "corrupt"
    bad.mkdir()
    (bad / "chroma.sqlite3").write_bytes(b"this is not an sqlite database" * 100)
    room = Topic(name="room", msg_type="String")
    mapper = MapEncoding(layers=[MapLayer(subscribes_to=room)], position=Topic(name="odom", msg_type="Odometry"),
                         map_topic=Topic(name="map", msg_type="OccupancyGrid"),
                         db_client=ChromaClient(db=ChromaDB(path=str(bad))), trigger=15.0, component_name="broken_map")
    with ComponentHarness(mapper) as h:
        h.feed("/map", M.OccupancyGrid(info=M.MapMetaData(resolution=0.5, width=20, height=20), data=np.zeros(400, np.int8)))
        h.feed("/odom", _odom(1.0))
        h.feed("/room", M.String(data="kitchen"))
        h.advance(15.0)
        h.wait_for(lambda: mapper.dropped_observations == 1, timeout=HANG_S, what="the observation reported dropped")
        assert h.health.is_component_fail
    assert any("[broken_map] 1 observation(s) of /room not stored in map 'map'" in r.getMessage() for r in caplog.records), \
        [r.getMessage() for r in caplog.records]
