"""ROS map_server YAML + image maps: load and save, with map_server's exact interpretation.

The YAML keys are those of the ROS 2 map_server (nav2_map_server ``map_io``): ``image``,
``resolution``, ``origin`` [x, y, yaw], ``free_thresh``, ``occupied_thresh``, ``negate`` (all
required) and ``mode`` (``trinary`` by default, or ``scale`` / ``raw``). Pixel to cell rules:

- shade = mean of the colour channels / maxval (in trinary mode an alpha channel, opaque =
  maxval, is averaged in with them, as map_server does); occ = shade if negate else 1 - shade;
- trinary: occ > occupied_thresh -> 100, occ < free_thresh -> 0, otherwise -1;
- scale: non-opaque pixels -> -1, then as trinary except the in-between band, which becomes
  ``rint(100 * (occ - free) / (occupied - free))``;
- raw: value = round(shade * 255); values outside 0..100 -> -1.

The first image row is the top of the map (largest y), so rows are flipped into the grid.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from emos.errors import EmosError

from .grid import OccupancyGridMap
from .image_io import MapImageError, read_image, write_pgm

__all__ = ["MapFileError", "MapMetadata", "load_map", "save_map", "image_to_grid", "grid_to_image", "MAP_MODES"]

MAP_MODES = ("trinary", "scale", "raw")
_REQUIRED = ("image", "resolution", "origin", "free_thresh", "occupied_thresh", "negate")


class MapFileError(EmosError, ValueError):
    """A map YAML that is missing a key, has a bad value, or points at an unreadable image."""


class MapMetadata(dict):
    """The parsed YAML values (image path resolved, thresholds validated)."""


def _number(doc: dict, key: str, path: Path) -> float:
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MapFileError(f"{path}: '{key}' must be a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise MapFileError(f"{path}: '{key}' must be finite, got {value!r}")
    return float(value)


def _check_thresholds(free: float, occupied: float, where: str) -> None:
    if not 0.0 <= free <= 1.0:
        raise MapFileError(f"{where}: 'free_thresh' must be in [0, 1], got {free}")
    if not 0.0 <= occupied <= 1.0:
        raise MapFileError(f"{where}: 'occupied_thresh' must be in [0, 1], got {occupied}")
    if not free < occupied:
        raise MapFileError(
            f"{where}: 'free_thresh' ({free}) must be lower than 'occupied_thresh' ({occupied})"
        )


def read_map_yaml(path: str | os.PathLike) -> MapMetadata:
    """Parse and validate a map_server YAML file (does not read the image)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise MapFileError(f"cannot read map file {p}: {exc.strerror or exc}") from exc
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MapFileError(f"{p}: invalid YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise MapFileError(f"{p}: expected a mapping of map_server keys, got {type(doc).__name__}")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise MapFileError(f"{p}: missing required key(s) {', '.join(repr(k) for k in missing)}")
    meta = MapMetadata()
    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise MapFileError(f"{p}: 'image' must be a file name, got {image!r}")
    image_path = Path(image)
    meta["image"] = image_path if image_path.is_absolute() else (p.parent / image_path)
    meta["resolution"] = _number(doc, "resolution", p)
    if meta["resolution"] <= 0:
        raise MapFileError(f"{p}: 'resolution' must be > 0 m/cell, got {meta['resolution']}")
    origin = doc["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapFileError(f"{p}: 'origin' must be a list [x, y, yaw] of 3 numbers, got {origin!r}")
    try:
        meta["origin"] = tuple(_number({"origin": v}, "origin", p) for v in origin)
    except MapFileError as exc:
        raise MapFileError(f"{p}: 'origin' must hold 3 numbers, got {origin!r}") from exc
    meta["free_thresh"] = _number(doc, "free_thresh", p)
    meta["occupied_thresh"] = _number(doc, "occupied_thresh", p)
    _check_thresholds(meta["free_thresh"], meta["occupied_thresh"], str(p))
    negate = doc["negate"]
    if isinstance(negate, bool) or negate in (0, 1):
        meta["negate"] = bool(negate)
    else:
        raise MapFileError(f"{p}: 'negate' must be 0/1 or true/false, got {negate!r}")
    mode = doc.get("mode", "trinary")
    if not isinstance(mode, str) or mode.lower() not in MAP_MODES:
        raise MapFileError(f"{p}: 'mode' must be one of {', '.join(MAP_MODES)}, got {mode!r}")
    meta["mode"] = mode.lower()
    return meta


def image_to_grid(
    channels: np.ndarray,
    maxval: int,
    alpha: np.ndarray | None,
    *,
    mode: str = "trinary",
    negate: bool = False,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.25,
) -> np.ndarray:
    """Convert image pixels (row 0 = top) to grid cells (row 0 = bottom) as map_server does."""
    if mode not in MAP_MODES:
        raise ValueError(f"image_to_grid: mode must be one of {MAP_MODES}, got {mode!r}")
    _check_thresholds(free_thresh, occupied_thresh, "image_to_grid")
    px = np.asarray(channels, dtype=np.float64)
    if px.ndim == 2:
        px = px[..., None]
    stack = [px[..., i] for i in range(px.shape[-1])]
    if mode == "trinary" and alpha is not None:
        # map_server folds alpha into the average in trinary mode, so a transparent white
        # pixel reads darker (unknown) while an opaque one stays free.
        stack.append(np.asarray(alpha, dtype=np.float64))
    shade = np.mean(stack, axis=0) / float(maxval)
    occ = shade if negate else 1.0 - shade
    cells = np.full(shade.shape, -1, dtype=np.int64)
    if mode == "raw":
        value = np.round(shade * 255.0)
        ok = (value >= 0) & (value <= 100)
        cells[ok] = value[ok].astype(np.int64)
    else:
        occupied = occupied_thresh < occ
        free = occ < free_thresh
        cells[occupied] = 100
        cells[free] = 0
        if mode == "scale":
            between = ~occupied & ~free
            cells[between] = np.rint(
                (occ[between] - free_thresh) / (occupied_thresh - free_thresh) * 100.0
            ).astype(np.int64)
            if alpha is not None:
                cells[np.asarray(alpha) < maxval] = -1
    return np.flipud(cells).astype(np.int8)


def load_map(path: str | os.PathLike) -> OccupancyGridMap:
    """Load a map_server YAML file and its image into an :class:`OccupancyGridMap`."""
    meta = read_map_yaml(path)
    try:
        channels, maxval, alpha = read_image(meta["image"])
    except MapImageError as exc:
        raise MapFileError(f"{path}: image {meta['image']} is unreadable: {exc}") from exc
    cells = image_to_grid(
        channels,
        maxval,
        alpha,
        mode=meta["mode"],
        negate=meta["negate"],
        occupied_thresh=meta["occupied_thresh"],
        free_thresh=meta["free_thresh"],
    )
    return OccupancyGridMap(data=cells, resolution=meta["resolution"], origin=meta["origin"])


def grid_to_image(
    grid: OccupancyGridMap,
    *,
    mode: str = "trinary",
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.25,
) -> np.ndarray:
    """Grid cells -> 8-bit image pixels (row 0 = top), following map_server's saver.

    trinary: free (<= free_thresh*100) 254, occupied (>= occupied_thresh*100) 0, else 205;
    scale: 255 * (100 - v) / 100, unknown 205; raw: the value itself, unknown 255.
    """
    if mode not in MAP_MODES:
        raise ValueError(f"grid_to_image: mode must be one of {MAP_MODES}, got {mode!r}")
    _check_thresholds(free_thresh, occupied_thresh, "grid_to_image")
    v = grid.data.astype(np.int64)
    unknown = (v < 0) | (v > 100)
    if mode == "trinary":
        px = np.full(v.shape, 205, dtype=np.int64)
        px[v <= int(round(free_thresh * 100))] = 254
        px[v >= int(round(occupied_thresh * 100))] = 0
        px[unknown] = 205
    elif mode == "scale":
        px = np.rint((100 - v) * 255.0 / 100.0).astype(np.int64)
        px[unknown] = 205
    else:
        px = v.copy()
        px[unknown] = 255
    return np.flipud(px)


def save_map(
    grid: OccupancyGridMap,
    yaml_path: str | os.PathLike,
    *,
    mode: str = "trinary",
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
    image_name: str | None = None,
) -> Path:
    """Write ``grid`` as a map_server YAML plus an 8-bit PGM next to it; returns the YAML path.

    The default thresholds are ROS map_saver's (0.65 / 0.196): with them the unknown grey
    (205, occ = 0.19608) reloads as unknown rather than free.

    ``raw`` mode stores every value exactly; ``trinary`` keeps -1/0/100 exactly. ``scale``
    is saved with free_thresh 0 and occupied_thresh 1 so every value 0..100 survives a reload,
    but (as with map_server) a greyscale PGM cannot mark unknown cells in scale mode: they
    come back as 20. Use ``raw`` to keep unknown cells and intermediate values.
    """
    yp = Path(yaml_path)
    if mode == "scale":
        # With the default band most values would be clipped to 0/100 on reload.
        free_thresh, occupied_thresh = 0.0, 1.0
    pixels = grid_to_image(grid, mode=mode, occupied_thresh=occupied_thresh, free_thresh=free_thresh)
    if mode == "trinary":
        # The thresholds written to the YAML must decode the three pixel values back to the
        # same classes (e.g. free_thresh 0.25 would turn unknown pixels, 205, into free).
        back = image_to_grid(pixels, 255, None, mode=mode, occupied_thresh=occupied_thresh, free_thresh=free_thresh)
        expected = np.full(grid.data.shape, -1, dtype=np.int8)
        expected[(grid.data >= 0) & (grid.data <= int(round(free_thresh * 100)))] = 0
        expected[grid.data >= int(round(occupied_thresh * 100))] = 100
        if not np.array_equal(back, expected):
            raise ValueError(
                f"save_map: thresholds free_thresh={free_thresh}, occupied_thresh={occupied_thresh} "
                "cannot encode free (254), unknown (205) and occupied (0) pixels distinctly; "
                "use free_thresh < 0.196 < occupied_thresh < 1"
            )
    img_name = image_name or (yp.stem + ".pgm")
    yp.parent.mkdir(parents=True, exist_ok=True)
    write_pgm(yp.parent / img_name, pixels, comment=f"EMOS map {grid.width}x{grid.height} @ {grid.resolution} m")
    doc: dict[str, Any] = {
        "image": img_name,
        "mode": mode,
        "resolution": float(grid.resolution),
        "origin": [float(v) for v in grid.origin],
        "negate": 0,
        "occupied_thresh": float(occupied_thresh),
        "free_thresh": float(free_thresh),
    }
    yp.write_text(yaml.safe_dump(doc, sort_keys=False))
    return yp
