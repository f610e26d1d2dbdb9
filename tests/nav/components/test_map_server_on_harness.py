"""The MapServer's maps from files and its save_map service, on the component harness (no
process tree): a PCD cloud becomes a grid, a YAML map round-trips through save_map. A missing or
malformed file failing a real run is tested in test_nav_components_faults.py."""
from __future__ import annotations

import numpy as np
import pytest

from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit


def _map_server(**config):
    from emos.actors.nav.components import MapServer, MapServerConfig

    return MapServer(component_name="map_server", config=MapServerConfig(**config))


def test_a_pcd_cloud_is_published_as_a_grid_of_its_height_slice(tmp_path):
    # Two posts above the floor and one point on it (below min_height 0.05 m: not an obstacle).
    pcd = tmp_path / "posts.pcd"
    pts = np.array([[0.0, 0.0, 0.5], [1.0, 0.5, 0.5], [1.0, 0.5, 0.01]], dtype=np.float32)
    pcd.write_bytes(b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n" + pts.tobytes())
    with ComponentHarness(_map_server(map_file_path=str(pcd), grid_resolution=0.1)) as h:
        g = h.latest("/map")
        assert g is not None, "the map is published on activation"
        assert g.info.resolution == np.float32(0.1) and int((g.data == 100).sum()) == 2
        h.advance(3.0)
        assert h.health.is_healthy


def test_save_map_service_round_trips(tmp_path):
    from emos.actors.nav.components.interfaces import SaveMapRequest
    from emos.actors.nav.maps import load_map
    from tests.nav.components.fake_base import write_room_map

    map_file = write_room_map(tmp_path / "room.yaml")
    with ComponentHarness(_map_server(map_file_path=map_file)) as h:
        bad = h.call("map_server/save_map", SaveMapRequest(file_location=str(tmp_path), file_name="../escape"))
        assert not bad.success and "plain name" in bad.message
        res = h.call("map_server/save_map", SaveMapRequest(file_location=str(tmp_path / "saved"), file_name="copy"))
        assert res.success, res.message
        assert np.array_equal(load_map(res.path).data, load_map(map_file).data)
        with pytest.raises(KeyError, match="serves no service 'map_server/nope' while active; services: \\['map_server/save_map'\\]"):
            h.call("map_server/nope", SaveMapRequest())
