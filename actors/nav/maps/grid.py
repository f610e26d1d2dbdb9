"""Occupancy grid with ROS ``nav_msgs/OccupancyGrid`` semantics.

``data[iy, ix]`` is an int8: -1 unknown, 0 free ... 100 occupied. Row 0 is the row of cells
nearest the origin (lowest y in the map frame), exactly as the flattened ROS message
(``index = iy * width + ix``). The origin is the pose (x, y, yaw) of the *corner* of cell
(0, 0) in the world frame; cell centres sit half a resolution inside.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

__all__ = ["OccupancyGridMap", "UNKNOWN", "FREE", "OCCUPIED"]

UNKNOWN = -1
FREE = 0
OCCUPIED = 100


def _check_data(value: np.ndarray) -> None:
    if value.ndim != 2 or value.shape[0] == 0 or value.shape[1] == 0:
        raise ValueError(
            f"OccupancyGridMap.data: expected a non-empty 2D array (height, width), got shape "
            f"{value.shape}"
        )
    bad = (value < -1) | (value > 100)
    if bad.any():
        iy, ix = np.argwhere(bad)[0]
        raise ValueError(
            f"OccupancyGridMap.data: values must be -1 (unknown) or 0..100, got {int(value[iy, ix])} "
            f"at cell (ix={ix}, iy={iy})"
        )


def _to_int8(value: Any) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iub":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"OccupancyGridMap.data: expected integer cell values, got dtype {arr.dtype}")
    # Range-check before the cast so 200 is not silently wrapped to -56.
    _check_data(arr.astype(np.int64))
    return np.ascontiguousarray(arr.astype(np.int8))


def _origin(value: Any) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in value)
    except TypeError as exc:
        raise TypeError(f"OccupancyGridMap.origin: expected (x, y, yaw), got {value!r}") from exc
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"OccupancyGridMap.origin: expected 3 finite numbers (x, y, yaw), got {value!r}")
    return vals


@attrs.define(eq=False)
class OccupancyGridMap:
    """A 2D occupancy grid: int8 cells, resolution (m/cell) and origin pose (x, y, yaw)."""

    data: np.ndarray = attrs.field(converter=_to_int8)
    resolution: float = attrs.field(converter=float, validator=V.finite_positive)
    origin: tuple[float, float, float] = attrs.field(default=(0.0, 0.0, 0.0), converter=_origin)
    frame_id: str = attrs.field(default="map")

    @property
    def width(self) -> int:
        """Number of cells along the map x axis (columns)."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Number of cells along the map y axis (rows)."""
        return int(self.data.shape[0])

    @property
    def size_m(self) -> tuple[float, float]:
        return self.width * self.resolution, self.height * self.resolution

    # ---- frames -------------------------------------------------------------------------
    def _rotation(self) -> tuple[float, float]:
        yaw = self.origin[2]
        return math.cos(yaw), math.sin(yaw)

    def world_to_map(self, points: np.ndarray) -> np.ndarray:
        """World (N, 2) points -> continuous coordinates in the map frame (metres from the origin corner)."""
        p = np.asarray(points, dtype=np.float64)
        c, s = self._rotation()
        dx = p[..., 0] - self.origin[0]
        dy = p[..., 1] - self.origin[1]
        return np.stack((c * dx + s * dy, -s * dx + c * dy), axis=-1)

    def map_to_world(self, points: np.ndarray) -> np.ndarray:
        """Map-frame (N, 2) metres -> world (N, 2)."""
        p = np.asarray(points, dtype=np.float64)
        c, s = self._rotation()
        x = c * p[..., 0] - s * p[..., 1] + self.origin[0]
        y = s * p[..., 0] + c * p[..., 1] + self.origin[1]
        return np.stack((x, y), axis=-1)

    def world_to_grid(self, points: np.ndarray) -> np.ndarray:
        """World (..., 2) points -> integer cell indices (..., 2) as (ix, iy); may be out of bounds."""
        m = self.world_to_map(points)
        return np.floor(m / self.resolution).astype(np.int64)

    def grid_to_world(self, cells: np.ndarray) -> np.ndarray:
        """Cell indices (..., 2) as (ix, iy) -> world coordinates of the cell centres."""
        c = np.asarray(cells, dtype=np.float64)
        return self.map_to_world((c + 0.5) * self.resolution)

    def in_bounds(self, cells: np.ndarray) -> np.ndarray:
        """Boolean mask of (ix, iy) cells that lie inside the grid."""
        c = np.asarray(cells)
        return (c[..., 0] >= 0) & (c[..., 0] < self.width) & (c[..., 1] >= 0) & (c[..., 1] < self.height)

    def values_at(self, points: np.ndarray, outside: int = UNKNOWN) -> np.ndarray:
        """Cell values at world points (..., 2); points outside the grid get ``outside``."""
        cells = self.world_to_grid(points)
        inside = self.in_bounds(cells)
        ix = np.where(inside, cells[..., 0], 0)
        iy = np.where(inside, cells[..., 1], 0)
        return np.where(inside, self.data[iy, ix], np.int8(outside)).astype(np.int8)

    def world_bounds(self) -> tuple[float, float, float, float]:
        """Axis-aligned world box (xmin, ymin, xmax, ymax) that contains the whole grid."""
        w, h = self.size_m
        corners = self.map_to_world(np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]]))
        return (
            float(corners[:, 0].min()),
            float(corners[:, 1].min()),
            float(corners[:, 0].max()),
            float(corners[:, 1].max()),
        )

    # ---- cell classes -------------------------------------------------------------------
    def occupied_mask(self, threshold: int = 65, unknown_is_occupied: bool = False) -> np.ndarray:
        """Cells whose value is >= ``threshold`` (and unknown cells when asked)."""
        if not 0 <= threshold <= 100:
            raise ValueError(f"occupied_mask: threshold must be in 0..100, got {threshold!r}")
        mask = self.data >= threshold
        if unknown_is_occupied:
            mask |= self.data == UNKNOWN
        return mask

    def free_mask(self, threshold: int = 25) -> np.ndarray:
        """Known cells whose value is <= ``threshold``."""
        return (self.data >= 0) & (self.data <= threshold)

    def copy_with(self, data: np.ndarray) -> OccupancyGridMap:
        """Same geometry, new cell values."""
        if np.shape(data) != self.data.shape:
            raise ValueError(f"copy_with: expected data of shape {self.data.shape}, got {np.shape(data)}")
        return OccupancyGridMap(data=data, resolution=self.resolution, origin=self.origin, frame_id=self.frame_id)

    def flat_data(self) -> np.ndarray:
        """Row-major int8 cells as in ``nav_msgs/OccupancyGrid.data``."""
        return self.data.reshape(-1)

    @classmethod
    def from_flat(
        cls,
        flat: np.ndarray,
        width: int,
        height: int,
        resolution: float,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
        frame_id: str = "map",
    ) -> OccupancyGridMap:
        """Build from a ROS-style flat array (``index = iy * width + ix``)."""
        arr = np.asarray(flat)
        if arr.size != width * height:
            raise ValueError(
                f"OccupancyGridMap.from_flat: expected width*height = {width * height} values, got {arr.size}"
            )
        return cls(data=arr.reshape(height, width), resolution=resolution, origin=origin, frame_id=frame_id)
