"""Zones: named polygons of a filter mask, and their rasterization into a mask grid.

A zone is ``name``, ``kind`` (``keepout`` or ``speed``), ``polygon`` [[x, y], ...] in the map
frame (metres) and, for speed zones, ``value`` (the limit: percent of the maximum speed for a
``speed_percent`` mask, m/s for ``speed_absolute``). The zones are stored in the mask YAML
(key ``zones``, which map_server ignores) so a mask can be listed and edited by name.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import attrs
import numpy as np

__all__ = ["ZONE_KINDS", "Zone", "points_in_polygon", "rasterize", "zone_from_dict"]

ZONE_KINDS = ("keepout", "speed")


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule for world points (..., 2) against one polygon (N, 2)."""
    p = np.asarray(points, dtype=float)
    poly = np.asarray(polygon, dtype=float)
    x, y = p[..., 0], p[..., 1]
    inside = np.zeros(x.shape, dtype=bool)
    xj, yj = poly[-1]
    for xi, yi in poly:
        crosses = (yi > y) != (yj > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = (xj - xi) * (y - yi) / (yj - yi) + xi
        inside ^= crosses & (x < x_cross)
        xj, yj = xi, yi
    return inside


@attrs.frozen
class Zone:
    name: str
    kind: str
    polygon: tuple[tuple[float, float], ...]
    value: float = 0.0

    def contains(self, points: np.ndarray) -> np.ndarray:
        return points_in_polygon(points, np.asarray(self.polygon))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "kind": self.kind, "polygon": [list(p) for p in self.polygon]}
        if self.kind == "speed":
            d["value"] = self.value
        return d


def zone_from_dict(doc: Any, where: str) -> Zone:
    """A zone from a mapping; ValueError naming ``where`` and the bad field."""
    if not isinstance(doc, dict):
        raise ValueError(f"{where}: a zone must be a mapping with name, kind, polygon[, value], got {doc!r}")
    name = doc.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{where}: zone 'name' must be a non-empty string, got {name!r}")
    kind = doc.get("kind")
    if kind not in ZONE_KINDS:
        raise ValueError(f"{where}: zone {name!r}: 'kind' must be one of {', '.join(ZONE_KINDS)}, got {kind!r}")
    poly = doc.get("polygon")
    pts: tuple[tuple[float, float], ...] = ()
    if isinstance(poly, (list, tuple)) and all(isinstance(p, (list, tuple)) and len(p) == 2 for p in poly):
        try:
            pts = tuple((float(p[0]), float(p[1])) for p in poly)
        except (TypeError, ValueError):
            pts = ()
    if len(pts) < 3 or not all(math.isfinite(c) for p in pts for c in p):
        raise ValueError(f"{where}: zone {name!r}: 'polygon' must be at least 3 finite [x, y] points, got {poly!r}")
    value = doc.get("value", 0.0)
    if kind == "speed" and (isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)):
        raise ValueError(f"{where}: speed zone {name!r}: 'value' must be a number, got {value!r}")
    return Zone(name=name, kind=kind, polygon=pts, value=float(value) if kind == "speed" else 0.0)


def rasterize(zones: Sequence[Zone], shape: tuple[int, int], resolution: float, origin: Sequence[float],
              cell_value: Any) -> np.ndarray:
    """int16 mask (rows, cols), 0 outside every zone; a cell whose centre is inside a zone gets
    ``cell_value(zone)`` (later zones win where they overlap). Axis-aligned origin only."""
    rows, cols = shape
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution
    centres = np.stack(np.meshgrid(xs, ys), axis=-1)
    out = np.zeros(shape, dtype=np.int16)
    for zone in zones:
        out[zone.contains(centres)] = cell_value(zone)
    return out
