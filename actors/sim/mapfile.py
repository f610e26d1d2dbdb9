"""Turn a ROS map (map_server YAML + PGM/PNG) into wall boxes for the simulator.

Reading the map is the navigation core's job (`emos.actors.nav.maps.load_map`, with all of
map_server's modes, thresholds, negate and alpha rules); this module only decides which cells
are walls and covers them with few boxes.
"""
from __future__ import annotations

import math
from pathlib import Path

import attrs
import numpy as np

from .primitives import Box


@attrs.define(frozen=True, eq=False)
class OccupancyMap:
    """``occupied`` is (rows, cols) bool with row 0 at the *bottom* (world +y grows with row)."""

    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float, float]  # world pose of the bottom-left corner of cell (0, 0)


def read_ros_map(yaml_path: str | Path, occupied_at: int = 65) -> OccupancyMap:
    """Cells at or above ``occupied_at`` (of 0..100) become walls; unknown cells stay open.

    Errors (missing file, key or image, bad values) are the map loader's ``MapFileError``,
    a ``ValueError`` naming the file and the problem.
    """
    from emos.actors.nav.maps import load_map

    grid = load_map(yaml_path)
    occupied = np.asarray(grid.data) >= occupied_at
    ox, oy, oyaw = grid.origin
    return OccupancyMap(np.ascontiguousarray(occupied), float(grid.resolution), (ox, oy, oyaw))


def merge_cells(occupied: np.ndarray) -> np.ndarray:
    """Cover the True cells of a 2D grid with few axis-aligned rectangles.

    Rows are split into runs (vectorized), then runs with the same column span in
    consecutive rows are stacked. Returns (N, 4) int rows of (row0, col0, row1, col1),
    half-open. A 200x200 room map becomes tens of boxes instead of thousands.
    """
    grid = np.asarray(occupied, dtype=bool)
    rows, cols = grid.shape
    padded = np.zeros((rows, cols + 2), dtype=np.int8)
    padded[:, 1:-1] = grid
    edges = np.diff(padded, axis=1)
    r_start, c_start = np.nonzero(edges == 1)
    _, c_end = np.nonzero(edges == -1)  # same row order: np.nonzero is row-major
    open_rects: dict[tuple[int, int], int] = {}  # (c0, c1) -> starting row
    done: list[tuple[int, int, int, int]] = []
    row_breaks = np.searchsorted(r_start, np.arange(rows + 1))
    for r in range(rows + 1):
        spans = set()
        if r < rows:
            lo, hi = row_breaks[r], row_breaks[r + 1]
            spans = set(zip(c_start[lo:hi].tolist(), c_end[lo:hi].tolist()))
        for span in [s for s in open_rects if s not in spans]:
            done.append((open_rects.pop(span), span[0], r, span[1]))
        for span in spans:
            open_rects.setdefault(span, r)
    return np.array(done, dtype=int).reshape(-1, 4)


def map_to_boxes(occ: OccupancyMap, height: float = 1.0) -> list[Box]:
    """Boxes extruding the occupied cells of ``occ`` in the world frame."""
    rects = merge_cells(occ.occupied)
    if len(rects) == 0:
        return []
    res = occ.resolution
    ox, oy, oyaw = occ.origin
    cy = (rects[:, 0] + rects[:, 2]) / 2 * res
    cx = (rects[:, 1] + rects[:, 3]) / 2 * res
    sy = (rects[:, 2] - rects[:, 0]) * res
    sx = (rects[:, 3] - rects[:, 1]) * res
    c, s = math.cos(oyaw), math.sin(oyaw)
    wx, wy = ox + c * cx - s * cy, oy + s * cx + c * cy
    return [Box((x, y), (a, b), height, oyaw) for x, y, a, b in zip(wx, wy, sx, sy)]
