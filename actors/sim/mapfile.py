"""Read a ROS map (map_server YAML + PGM/PNG) and turn occupied cells into wall boxes.

Kept deliberately small and independent of the navigation map server: the simulator only
needs "which cells are occupied" and the cell-to-world transform.
"""
from __future__ import annotations

import math
from pathlib import Path

import attrs
import numpy as np
import yaml

from . import _deps
from .primitives import Box


@attrs.define(frozen=True, eq=False)
class OccupancyMap:
    """``occupied`` is (rows, cols) bool with row 0 at the *bottom* (world +y grows with row)."""

    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float, float]  # world pose of the bottom-left corner of cell (0, 0)


def read_ros_map(yaml_path: str | Path) -> OccupancyMap:
    """Parse a map_server YAML and its image (trinary/scale modes, ``negate``, thresholds)."""
    yaml_path = Path(yaml_path)
    if not yaml_path.is_file():
        raise FileNotFoundError(f"ROS map YAML not found: {yaml_path}")
    with yaml_path.open() as fh:
        meta = yaml.safe_load(fh)
    if not isinstance(meta, dict):
        raise ValueError(f"{yaml_path}: expected a YAML mapping with image, resolution, origin")
    missing = [k for k in ("image", "resolution", "origin") if k not in meta]
    if missing:
        raise ValueError(f"{yaml_path}: missing required key(s) {missing}")
    resolution = float(meta["resolution"])
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"{yaml_path}: resolution must be > 0, got {meta['resolution']!r}")
    origin = [float(v) for v in meta["origin"]]
    if len(origin) != 3:
        raise ValueError(f"{yaml_path}: origin must be [x, y, yaw], got {meta['origin']!r}")
    image_path = Path(meta["image"])
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    if not image_path.is_file():
        raise FileNotFoundError(f"{yaml_path}: map image not found: {image_path}")
    pixels = np.asarray(_deps.pil_image().open(image_path).convert("L"), dtype=float)
    occ_prob = pixels / 255.0 if int(meta.get("negate", 0)) else (255.0 - pixels) / 255.0
    occupied = occ_prob > float(meta.get("occupied_thresh", 0.65))
    # Image row 0 is the top of the map; flip so row index grows with world y.
    return OccupancyMap(np.ascontiguousarray(occupied[::-1]), resolution, (origin[0], origin[1], origin[2]))


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
