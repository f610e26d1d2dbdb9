"""Costmap filters from mask maps: keepout zones and speed-limit zones (Nav2 semantics).

A mask is a ROS map_server YAML + image (read by :func:`~emos.actors.nav.maps.load_map`, so
``mode: scale`` masks made for Nav2 load unchanged) with these extra keys, which stand in for
Nav2's ``CostmapFilterInfo`` message:

- ``filter_type``: ``keepout`` (Nav2 type 0), ``speed_percent`` (1) or ``speed_absolute`` (2);
- ``base``, ``multiplier`` (speed masks): a cell of mask value ``v`` in 1..100 limits the speed
  to ``base + multiplier * v`` (percent of the maximum, or m/s); 0 and unknown cells: no limit;
- ``zones`` (optional): the named polygons the mask was drawn from (:mod:`.zones`), used to name
  a zone in errors ("the goal is inside keepout zone 'kitchen'").

Keepout: mask value 100 is lethal (never planned or driven through); 1..99 add a graded cost
(``v * 254 / 100``), as Nav2's KeepoutFilter. Every limit a speed mask can give is checked at
load: out of range (percent not in (0, 100], absolute not > 0) refuses the mask, naming the
file and the value.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import attrs
import numpy as np
import yaml

from ..maps import MapFileError, load_map
from ..maps.grid import OccupancyGridMap
from .costs import LETHAL_OBSTACLE, NO_INFORMATION
from .zones import Zone, zone_from_dict

__all__ = ["FILTER_TYPES", "FilterMask", "FilterMaskError", "KeepoutFilter", "KeepoutObstacles", "SpeedFilter", "SpeedLimit",
           "check_speed_limit", "load_filter_mask"]

FILTER_TYPES = ("keepout", "speed_percent", "speed_absolute")


class FilterMaskError(MapFileError):
    """A filter mask file that cannot be used (bad keys, out-of-range speed limits)."""


@attrs.frozen
class SpeedLimit:
    """Nav2's ``SpeedLimit`` message: ``speed_limit`` in percent (``percentage``) or m/s."""

    percentage: bool
    speed_limit: float

    def cap(self, max_speed: float) -> float:
        """The speed limit in m/s for a robot whose maximum is ``max_speed``."""
        return max_speed * self.speed_limit / 100.0 if self.percentage else min(max_speed, self.speed_limit)


@attrs.frozen
class FilterMask:
    path: Path
    filter_type: str
    grid: OccupancyGridMap
    base: float = 0.0
    multiplier: float = 1.0
    zones: tuple[Zone, ...] = ()

    def values_at(self, points: np.ndarray) -> np.ndarray:
        return self.grid.values_at(np.asarray(points, dtype=float), outside=-1)

    def zone_name_at(self, point: np.ndarray) -> str:
        """The name of the zone holding ``point``: a named polygon, else the mask file and cell."""
        p = np.asarray(point, dtype=float)[:2]
        for zone in reversed(self.zones):
            if bool(zone.contains(p[None])[0]):
                return f"{zone.name!r} ({self.path.name})"
        ix, iy = self.grid.world_to_grid(p)
        return f"of mask {self.path.name} at cell ({ix}, {iy})"


def _filter_type(value: Any, where: Path) -> str:
    if isinstance(value, int) and not isinstance(value, bool) and 0 <= value < len(FILTER_TYPES):
        return FILTER_TYPES[value]  # Nav2's CostmapFilterInfo type numbers
    if value in FILTER_TYPES:
        return str(value)
    raise FilterMaskError(f"{where}: 'filter_type' must be one of {', '.join(FILTER_TYPES)} (or 0, 1, 2), got {value!r}")


def _finite(doc: dict, key: str, default: float, where: Path) -> float:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise FilterMaskError(f"{where}: {key!r} must be a finite number, got {value!r}")
    return float(value)


def check_speed_limit(limit: float, filter_type: str) -> str | None:
    """What is wrong with a speed limit for a ``speed_percent`` / ``speed_absolute`` mask, or None."""
    if filter_type == "speed_percent" and not 0.0 < limit <= 100.0:
        return "expected a percentage in (0, 100]"
    if filter_type == "speed_absolute" and not limit > 0.0:
        return "expected a speed > 0 m/s"
    return None


def load_filter_mask(path: str | os.PathLike, filter_type: str | None = None) -> FilterMask:
    """Load and validate a mask; ``filter_type`` (keepout / speed) is what the caller expects."""
    p = Path(os.path.expanduser(str(path)))
    try:
        grid = load_map(p)
    except MapFileError as exc:  # one error type for every bad mask; the message names the file
        raise FilterMaskError(str(exc)) from exc
    doc = yaml.safe_load(p.read_text()) or {}
    if "filter_type" in doc:
        kind = _filter_type(doc["filter_type"], p)
    elif filter_type == "keepout":
        kind = "keepout"
    else:
        raise FilterMaskError(f"{p}: a speed mask needs 'filter_type': speed_percent or speed_absolute")
    if filter_type is not None and not kind.startswith(filter_type):
        raise FilterMaskError(f"{p}: expected a {filter_type} mask, the file says filter_type {kind!r}")
    base, multiplier = _finite(doc, "base", 0.0, p), _finite(doc, "multiplier", 1.0, p)
    raw_zones = doc.get("zones") or []
    if not isinstance(raw_zones, list):
        raise FilterMaskError(f"{p}: 'zones' must be a list of zones, got {type(raw_zones).__name__}")
    try:
        zones = tuple(zone_from_dict(z, str(p)) for z in raw_zones)
    except ValueError as exc:
        raise FilterMaskError(str(exc)) from None
    if kind != "keepout":
        for zone in zones:
            problem = check_speed_limit(zone.value, kind) if zone.kind == "speed" else None
            if problem:
                raise FilterMaskError(f"{p}: speed zone {zone.name!r}: value {zone.value:g} is out of range for "
                                      f"{kind}: {problem}")
        values = np.unique(grid.data[grid.data > 0]).astype(int)
        for v in values:
            limit = base + multiplier * float(v)
            problem = check_speed_limit(limit, kind)
            if problem:
                iy, ix = np.argwhere(grid.data == v)[0]
                raise FilterMaskError(f"{p}: speed limit {limit:g} (mask value {v} = base {base:g} + multiplier "
                                      f"{multiplier:g} * {v}, first at cell ({ix}, {iy})) is out of range for "
                                      f"{kind}: {problem}")
    return FilterMask(path=p, filter_type=kind, grid=grid, base=base, multiplier=multiplier, zones=zones)


def _cell_centres(geometry: OccupancyGridMap) -> np.ndarray:
    rows, cols = geometry.data.shape
    ix, iy = np.meshgrid(np.arange(cols), np.arange(rows))
    return geometry.grid_to_world(np.stack([ix, iy], axis=-1))


class KeepoutFilter:
    """Raises the master costs where the keepout mask marks cells (100: lethal)."""

    def __init__(self, mask: FilterMask) -> None:
        if mask.filter_type != "keepout":
            raise FilterMaskError(f"{mask.path}: KeepoutFilter needs a keepout mask, got {mask.filter_type!r}")
        self.mask = mask

    def lethal_cells(self, geometry: OccupancyGridMap) -> np.ndarray:
        """Boolean (rows, cols) of ``geometry``'s cells that are keepout (mask value 100)."""
        return self.mask.values_at(_cell_centres(geometry)) >= 100

    def update_master(self, master: np.ndarray, geometry: OccupancyGridMap) -> np.ndarray:
        v = self.mask.values_at(_cell_centres(geometry)).astype(np.int64)
        known = v > 0
        cost = np.where(v >= 100, LETHAL_OBSTACLE, (v * LETHAL_OBSTACLE) // 100).astype(np.uint8)
        take = known & ((master == NO_INFORMATION) | (master < cost))
        master[take] = cost[take]
        return master

    def zone_at(self, point: np.ndarray) -> str | None:
        """The keepout zone's name when ``point`` (x, y) is in a lethal keepout cell, else None."""
        p = np.asarray(point, dtype=float)[:2]
        if int(self.mask.values_at(p[None])[0]) >= 100:
            return self.mask.zone_name_at(p)
        return None


class KeepoutObstacles:
    """A keepout mask's zones as obstacle points round the robot, for what drives it (the
    Controller's algorithms, the DriveManager's swept check): the edges of the lethal cells
    (mask value 100), a point every half cell along each side that faces a cell outside the zone,
    so a footprint kept clear of the points stays out of the zone's cells.

    :meth:`around` gives the points near the robot in its own frame. A robot already inside a
    zone (its centre in a lethal cell: a zone drawn under it, a localization jump) gets none: it
    must be able to drive out, and nothing drove it in that this could undo; the edge points its
    footprint already touches are left out too, so it can back away from a zone it grazed."""

    def __init__(self, mask: FilterMask) -> None:
        self.filter = KeepoutFilter(mask)
        self.points = self._edge_points(mask.grid)

    @staticmethod
    def _edge_points(grid: OccupancyGridMap) -> np.ndarray:
        lethal = np.asarray(grid.data) >= 100
        if not lethal.any():
            return np.zeros((0, 2))
        padded = np.pad(lethal, 1, constant_values=False)  # off the mask: no zone
        iy, ix = np.nonzero(lethal)
        half = 0.5
        offsets = np.array([-half, 0.0, half])
        pts = []
        # (neighbour's row and column step, the side's fixed coordinate, which coordinate runs along it)
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            open_side = ~padded[iy + 1 + dy, ix + 1 + dx]
            cx, cy = ix[open_side] + 0.5, iy[open_side] + 0.5
            for o in offsets:
                if dx:
                    pts.append(np.c_[cx + dx * half, cy + o])
                else:
                    pts.append(np.c_[cx + o, cy + dy * half])
        cells = np.unique(np.round(np.vstack(pts) * 2).astype(np.int64), axis=0) / 2.0  # shared corners once
        out: np.ndarray = grid.map_to_world(cells * grid.resolution)
        return out

    def around(self, pose: np.ndarray, reach: float, clear: float = 0.0) -> tuple[np.ndarray, str | None]:
        """((M, 2) edge points within ``reach`` m of the robot at ``pose`` (x, y, yaw in the mask's
        frame), in the robot's frame, leaving out those within ``clear`` m of its centre (its
        footprint); the zone the robot's centre is in, else None (and then no points))."""
        x, y, yaw = (float(v) for v in np.asarray(pose, dtype=float)[:3])
        inside = self.filter.zone_at(np.array([x, y]))
        if inside is not None or len(self.points) == 0:
            return np.zeros((0, 2)), inside
        d = self.points - (x, y)
        dist = np.hypot(d[:, 0], d[:, 1])
        near = d[(dist <= reach) & (dist > clear)]
        c, s = math.cos(yaw), math.sin(yaw)
        return np.c_[c * near[:, 0] + s * near[:, 1], -s * near[:, 0] + c * near[:, 1]], None

    def zone_by(self, point: np.ndarray) -> str:
        """The name of the zone whose edge passes through (or nearest) ``point`` (x, y)."""
        p = np.asarray(point, dtype=float)[:2]
        q = 0.25 * self.filter.mask.grid.resolution
        for dx, dy in ((0, 0), (q, 0), (-q, 0), (0, q), (0, -q), (q, q), (-q, q), (q, -q), (-q, -q)):
            name = self.filter.zone_at(p + (dx, dy))
            if name is not None:
                return name
        return f"of mask {self.filter.mask.path.name}"


class SpeedFilter:
    """Speed limit at a point, as Nav2's SpeedFilter publishes it on ``speed_limit``."""

    def __init__(self, mask: FilterMask) -> None:
        if not mask.filter_type.startswith("speed"):
            raise FilterMaskError(f"{mask.path}: SpeedFilter needs a speed mask, got {mask.filter_type!r}")
        self.mask = mask

    def limit_at(self, point: np.ndarray) -> SpeedLimit | None:
        """The limit at (x, y), or None (no limit: mask value 0, unknown or off the mask)."""
        v = int(self.mask.values_at(np.asarray(point, dtype=float)[None, :2])[0])
        if v <= 0:
            return None
        return SpeedLimit(percentage=self.mask.filter_type == "speed_percent",
                          speed_limit=self.mask.base + self.mask.multiplier * v)

    def capped(self, cmds: np.ndarray, point: np.ndarray, max_speed: float) -> np.ndarray:
        """``cmds`` ((n, 3): vx, vy, omega) within the limit at ``point``: each command whose
        linear speed is above it is scaled down whole, keeping its curvature (the Controller's and
        the DriveManager's cap). ``max_speed``: the robot's, for a percentage limit."""
        cmds = np.asarray(cmds, dtype=float).reshape(-1, 3)
        limit = self.limit_at(point)
        if limit is None:
            return cmds
        cap = limit.cap(max_speed)
        speed = np.hypot(cmds[:, 0], cmds[:, 1])
        return cmds * np.where(speed > cap, cap / np.maximum(speed, 1e-12), 1.0)[:, None]
