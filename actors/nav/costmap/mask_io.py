"""Write zones as a ROS-style filter mask (YAML + PGM) that :func:`.filters.load_filter_mask`
and Nav2's map_server both read (``mode: scale``: a mask value v is the pixel 255 * (100 - v) / 100)."""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..maps import load_map, save_map
from ..maps.grid import OccupancyGridMap
from .filters import FilterMaskError, check_speed_limit, load_filter_mask
from .zones import Zone, rasterize

__all__ = ["write_mask", "zone_mask_paths", "load_zones", "save_zones", "edit_zone"]


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


# The zones of a map, as `emos map zones MAP.yaml ...` and the web UI's zone editor edit them: two
# masks beside the map, <stem>_keepout.yaml and <stem>_speed.yaml, each listing its zones by name.
def zone_mask_paths(map_yaml: str | os.PathLike) -> dict[str, Path]:
    path = Path(map_yaml)
    return {"keepout": path.with_name(f"{path.stem}_keepout.yaml"), "speed": path.with_name(f"{path.stem}_speed.yaml")}


def load_zones(map_yaml: str | os.PathLike) -> tuple[list[Zone], str]:
    """The zones of ``map_yaml``'s masks and the speed mask's type (``speed_percent`` if none)."""
    zones: list[Zone] = []
    speed_type = "speed_percent"
    for kind, path in zone_mask_paths(map_yaml).items():
        if path.exists():
            mask = load_filter_mask(path, kind)
            zones.extend(mask.zones)
            if kind == "speed":
                speed_type = mask.filter_type
    return zones, speed_type


def save_zones(map_yaml: str | os.PathLike, zones: Sequence[Zone], speed_type: str) -> list[Path]:
    """Write both masks of ``map_yaml`` (a mask with no zones left is rewritten empty, not removed)."""
    grid = load_map(map_yaml)
    written = []
    for kind, path in zone_mask_paths(map_yaml).items():
        mine = [z for z in zones if z.kind == kind]
        if mine or path.exists():
            written.append(write_mask(path, mine, "keepout" if kind == "keepout" else speed_type, grid))
    return written


def edit_zone(map_yaml: str | os.PathLike, verb: str, name: str, kind: str | None = None, polygon: Sequence[Sequence[float]] | None = None,
              value: float | None = None, speed_type: str | None = None) -> list[Path]:
    """``add``, ``set`` (change the given fields) or ``remove`` the zone ``name`` of ``map_yaml``
    and write its masks; ValueError (or FilterMaskError) naming the zone and the problem, with
    nothing written. ``speed_type``: ``percent`` or ``absolute`` (default: the mask's)."""
    from .zones import zone_from_dict

    zones, current = load_zones(map_yaml)
    if speed_type:
        if speed_type not in ("percent", "absolute"):
            raise ValueError(f"speed type must be percent or absolute, got {speed_type!r}")
        current = f"speed_{speed_type}"
    by_name = {z.name: z for z in zones}
    if verb == "remove":
        if name not in by_name:
            raise ValueError(f"no zone named {name!r} in {map_yaml}'s masks; zones: {', '.join(by_name) or 'none'}")
        del by_name[name]
    elif verb in ("add", "set"):
        if verb == "add" and name in by_name:
            raise ValueError(f"zone {name!r} already exists in {map_yaml}'s masks (use `set` to change it)")
        if verb == "set" and name not in by_name:
            raise ValueError(f"no zone named {name!r} in {map_yaml}'s masks; zones: {', '.join(by_name) or 'none'}")
        doc: dict[str, Any] = by_name[name].to_dict() if verb == "set" else {"name": name}
        if kind:
            doc["kind"] = kind
        if polygon is not None:
            doc["polygon"] = [list(p) for p in polygon]
        if value is not None:
            doc["value"] = value
        if doc.get("kind") == "speed" and "value" not in doc:
            raise ValueError(f"speed zone {name!r} needs a value")
        by_name[name] = zone_from_dict(doc, str(map_yaml))
    else:
        raise ValueError(f"zone edit: verb must be add, set or remove, got {verb!r}")
    return save_zones(map_yaml, list(by_name.values()), current)
