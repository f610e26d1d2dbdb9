"""``emos map zones``: zones added, edited, listed and removed write masks the Planner loads;
out-of-range speed values are refused and leave the masks as they were."""
from __future__ import annotations

import argparse

import numpy as np
import pytest

from emos.actors.nav.costmap import SpeedFilter, load_filter_mask
from emos.tools.cli import map_zones

from .helpers import write_room

pytestmark = pytest.mark.unit


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    parser = argparse.ArgumentParser()
    map_zones.add_parser(parser.add_subparsers(dest="map_verb"))
    code = map_zones.run(parser.parse_args(["zones", *argv]))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_zones_round_trip_through_masks(tmp_path, capsys):
    map_file, _ = write_room(tmp_path)
    assert _run(capsys, map_file, "add", "kitchen", "--kind", "keepout", "--polygon", "1,1 3,1 3,2 1,2")[0] == 0
    assert _run(capsys, map_file, "add", "hall", "--kind", "speed", "--value", "40", "--polygon", "4,0 6,0 6,2 4,2")[0] == 0
    code, _, err = _run(capsys, map_file, "add", "ramp", "--kind", "speed", "--value", "140", "--polygon", "0,0 1,0 1,1")
    assert code == 2 and "room_speed.yaml: speed zone 'ramp': value 140 is out of range for speed_percent" in err
    assert _run(capsys, map_file, "set", "hall", "--value", "30")[0] == 0
    code, out, _ = _run(capsys, map_file, "list")
    assert "kitchen" in out and "hall" in out and "30%" in out and "ramp" not in out
    masks = map_zones.mask_paths(tmp_path / "room.yaml")
    keepout = load_filter_mask(masks["keepout"], "keepout")
    assert keepout.values_at(np.array([[2.0, 1.5]]))[0] == 100 and keepout.values_at(np.array([[2.0, 3.0]]))[0] == 0
    limit = SpeedFilter(load_filter_mask(masks["speed"], "speed")).limit_at(np.array([5.0, 1.0]))
    assert limit is not None and limit.percentage and limit.speed_limit == pytest.approx(30.0)
    assert _run(capsys, map_file, "remove", "kitchen")[0] == 0
    assert load_filter_mask(masks["keepout"], "keepout").values_at(np.array([[2.0, 1.5]]))[0] == 0
    code, _, err = _run(capsys, map_file, "remove", "nope")
    assert code == 2 and "no zone named 'nope'" in err


def test_zones_import_from_yaml_and_bad_polygons(tmp_path, capsys):
    map_file, _ = write_room(tmp_path)
    zones = tmp_path / "zones.yaml"
    zones.write_text("- {name: dock, kind: speed, value: 0.2, polygon: [[0, 0], [1, 0], [1, 1]]}\n")
    assert _run(capsys, map_file, "import", str(zones), "--speed-type", "absolute")[0] == 0
    mask = load_filter_mask(map_zones.mask_paths(tmp_path / "room.yaml")["speed"], "speed")
    assert mask.filter_type == "speed_absolute" and mask.zones[0].name == "dock"
    code, _, err = _run(capsys, map_file, "add", "x", "--kind", "keepout", "--polygon", "1,1 2,2")
    assert code == 2 and "zone 'x': 'polygon' must be at least 3" in err
