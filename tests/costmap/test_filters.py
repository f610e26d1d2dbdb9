"""Filter masks: keepout and speed zones loaded from ROS-style mask YAMLs, checked at load."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from emos.actors.nav.costmap import CostmapConfig, FilterMaskError, LayeredCostmap, SpeedFilter, Zone, load_filter_mask
from emos.actors.nav.costmap.mask_io import write_mask

from .helpers import KEEPOUT, room_grid

pytestmark = pytest.mark.unit

SLOW = Zone(name="hall", kind="speed", polygon=((0.5, 0.5), (2.0, 0.5), (2.0, 2.0), (0.5, 2.0)), value=40.0)


def test_keepout_mask_round_trips_and_names_its_zone(tmp_path):
    grid = room_grid()
    path = write_mask(tmp_path / "keepout.yaml", [KEEPOUT], "keepout", grid)
    mask = load_filter_mask(path, "keepout")
    assert mask.filter_type == "keepout" and mask.zones == (KEEPOUT,)
    costmap = LayeredCostmap(CostmapConfig(enabled=True, keepout_mask=str(path)), 0.15)
    master = costmap.set_map(grid)
    assert master.cost_at(np.array([3.0, 1.0])) == 254 and master.cost_at(np.array([1.0, 2.0])) == 0
    assert costmap.keepout_zone_at(np.array([3.0, 1.0])) == "'wet_floor' (keepout.yaml)"
    assert costmap.keepout_zone_at(np.array([1.0, 1.0])) is None
    planning = costmap.planning_grid(grid)
    assert planning.values_at(np.array([3.0, 1.0])) == 100 and grid.values_at(np.array([3.0, 1.0])) == 0


def test_speed_zones_percent_and_absolute_follow_nav2_semantics(tmp_path):
    grid = room_grid()
    percent = SpeedFilter(load_filter_mask(write_mask(tmp_path / "pct.yaml", [SLOW], "speed_percent", grid), "speed"))
    limit = percent.limit_at(np.array([1.0, 1.0]))
    assert limit is not None and limit.percentage and limit.speed_limit == pytest.approx(40.0)
    assert limit.cap(0.5) == pytest.approx(0.2)
    assert percent.limit_at(np.array([4.0, 3.0])) is None  # mask value 0: no limit
    fast = Zone(name="hall", kind="speed", polygon=SLOW.polygon, value=0.3)
    absolute = SpeedFilter(load_filter_mask(write_mask(tmp_path / "abs.yaml", [fast], "speed_absolute", grid), "speed"))
    limit = absolute.limit_at(np.array([1.0, 1.0]))
    assert limit is not None and not limit.percentage and limit.speed_limit == pytest.approx(0.3)
    assert limit.cap(0.5) == pytest.approx(0.3) and limit.cap(0.2) == pytest.approx(0.2)


def test_speed_zone_value_out_of_range_is_refused_naming_file_and_value(tmp_path):
    grid = room_grid()
    path = write_mask(tmp_path / "pct.yaml", [SLOW], "speed_percent", grid)
    doc = yaml.safe_load(path.read_text())
    doc["multiplier"] = 3.0  # mask value 40 -> 120 %
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(FilterMaskError, match=r"pct\.yaml: speed limit 120 \(mask value 40.*out of range for speed_percent"):
        load_filter_mask(path, "speed")
    # Refused at definition: the config validator loads the mask.
    with pytest.raises(FilterMaskError, match=r"pct\.yaml.*120"):
        CostmapConfig(speed_mask=str(path))
    # A zone's own value out of range is refused by name, when writing and when loading.
    too_fast = Zone(name="ramp", kind="speed", polygon=SLOW.polygon, value=150.0)
    with pytest.raises(FilterMaskError, match=r"bad\.yaml: speed zone 'ramp': value 150 is out of range"):
        write_mask(tmp_path / "bad.yaml", [too_fast], "speed_percent", grid)
    negative = Zone(name="dock", kind="speed", polygon=SLOW.polygon, value=-0.2)
    with pytest.raises(FilterMaskError, match=r"neg\.yaml: speed zone 'dock': value -0.2 is out of range for speed_absolute"):
        write_mask(tmp_path / "neg.yaml", [negative], "speed_absolute", grid)


def test_malformed_masks_are_refused_naming_the_file(tmp_path):
    grid = room_grid()
    path = write_mask(tmp_path / "k.yaml", [KEEPOUT], "keepout", grid)
    doc = yaml.safe_load(path.read_text())
    with pytest.raises(FilterMaskError, match=r"k\.yaml: expected a speed mask, the file says filter_type 'keepout'"):
        load_filter_mask(path, "speed")
    doc["filter_type"] = "slow"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(FilterMaskError, match=r"k\.yaml: 'filter_type' must be one of keepout, speed_percent"):
        load_filter_mask(path, "keepout")
    doc["filter_type"] = "keepout"
    doc["zones"] = [{"name": "x", "kind": "keepout", "polygon": [[0, 0], [1, 1]]}]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(FilterMaskError, match=r"k\.yaml: zone 'x': 'polygon' must be at least 3"):
        load_filter_mask(path, "keepout")
    (tmp_path / "nopgm.yaml").write_text(yaml.safe_dump({**doc, "image": "missing.pgm", "zones": []}))
    with pytest.raises(FilterMaskError, match=r"nopgm\.yaml: image .*missing\.pgm is unreadable"):
        load_filter_mask(tmp_path / "nopgm.yaml", "keepout")
    with pytest.raises(FilterMaskError, match="cannot read map file .*absent.yaml"):
        CostmapConfig(keepout_mask=str(tmp_path / "absent.yaml"))
