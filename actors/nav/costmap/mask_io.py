"""Write zones as a ROS-style filter mask (YAML + PGM) that :func:`.filters.load_filter_mask`
and Nav2's map_server both read (``mode: scale``: a mask value v is the pixel 255 * (100 - v) / 100)."""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from ..maps import save_map
from ..maps.grid import OccupancyGridMap
from .filters import FilterMaskError, check_speed_limit, load_filter_mask
from .zones import Zone, rasterize

__all__ = ["write_mask"]


def write_mask(yaml_path: str | os.PathLike, zones: Sequence[Zone], filter_type: str, geometry: OccupancyGridMap) -> Path:
    """Rasterize ``zones`` of one kind on ``geometry``'s cells and write the mask; returns the YAML
    path. Keepout zones are 100; a speed zone's cell is its value in percent (``speed_percent``) or
    in units of ``multiplier`` m/s (``speed_absolute``). Out-of-range speed values are refused before
    anything is written; the result is re-loaded to check it."""
    if filter_type != "keepout":
        for zone in zones:  # refused before anything is written: the old mask stays as it was
            problem = check_speed_limit(zone.value, filter_type) if zone.kind == "speed" else None
            if problem:
                raise FilterMaskError(f"{yaml_path}: speed zone {zone.name!r}: value {zone.value:g} is out of range for "
                                      f"{filter_type}: {problem}")
    if filter_type == "keepout":
        chosen = [z for z in zones if z.kind == "keepout"]
        multiplier = 1.0
        data = rasterize(chosen, geometry.data.shape, geometry.resolution, geometry.origin, lambda z: 100)
    else:
        chosen = [z for z in zones if z.kind == "speed"]
        top = max([z.value for z in chosen] + [1.0]) if filter_type == "speed_absolute" else 100.0
        multiplier = 1.0 if filter_type == "speed_percent" else (0.01 if top <= 1.0 else math.ceil(top) / 100.0)
        data = rasterize(chosen, geometry.data.shape, geometry.resolution, geometry.origin,
                         lambda z: int(np.clip(round(z.value / multiplier), 1, 100)))
    if abs(geometry.origin[2]) > 1e-12:
        raise ValueError(f"write_mask: {yaml_path}: the map's origin is rotated (yaw {geometry.origin[2]}); masks need an axis-aligned map")
    path = save_map(geometry.copy_with(data.astype(np.int8)), yaml_path, mode="scale")
    doc = yaml.safe_load(path.read_text())
    doc.update({"filter_type": filter_type, "base": 0.0, "multiplier": multiplier, "zones": [z.to_dict() for z in chosen]})
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    load_filter_mask(path, "keepout" if filter_type == "keepout" else "speed")  # refuses a bad value naming the zone
    return path
