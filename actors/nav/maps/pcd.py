"""Point cloud (PCD) map files: read the x, y, z of a PCD and project a height slice onto a grid."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .grid import FREE, OCCUPIED, OccupancyGridMap
from .map_yaml import MapFileError

__all__ = ["read_pcd", "cloud_to_grid"]

_SIZES = {("F", 4): np.float32, ("F", 8): np.float64, ("I", 1): np.int8, ("I", 2): np.int16, ("I", 4): np.int32,
          ("U", 1): np.uint8, ("U", 2): np.uint16, ("U", 4): np.uint32}


def read_pcd(path: str | os.PathLike) -> np.ndarray:
    """(N, 3) float64 x, y, z of an ``ascii`` or ``binary`` PCD file (non-finite points dropped)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise MapFileError(f"cannot read point cloud map {p}: {exc.strerror or exc}") from exc
    header: dict[str, list[str]] = {}
    offset = 0
    while True:
        end = raw.find(b"\n", offset)
        if end < 0:
            raise MapFileError(f"{p}: not a PCD file (no DATA line in the header)")
        line = raw[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    try:
        fields = header["FIELDS"]
        sizes = [int(v) for v in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(fields))]
        n = int(header["POINTS"][0]) if "POINTS" in header else int(header["WIDTH"][0]) * int(header["HEIGHT"][0])
        mode = header["DATA"][0].lower()
    except (KeyError, ValueError, IndexError) as exc:
        raise MapFileError(f"{p}: malformed PCD header ({exc})") from exc
    missing = [f for f in "xyz" if f not in fields]
    if missing:
        raise MapFileError(f"{p}: PCD has no field(s) {', '.join(missing)} (fields: {' '.join(fields)})")
    cols: list[tuple[str, np.dtype]] = []
    for name, size, typ, count in zip(fields, sizes, types, counts):
        dtype = _SIZES.get((typ.upper(), size))
        if dtype is None:
            raise MapFileError(f"{p}: unsupported PCD field type {typ}{size} for {name!r}")
        cols += [(name if count == 1 else f"{name}_{k}", np.dtype(dtype).newbyteorder("<")) for k in range(count)]
    if mode == "ascii":
        try:
            table = np.loadtxt(raw[offset:].decode("ascii").splitlines(), ndmin=2)
        except ValueError as exc:
            raise MapFileError(f"{p}: malformed ASCII PCD data ({exc})") from exc
        names = [c[0] for c in cols]
        if table.shape[1] != len(names):
            raise MapFileError(f"{p}: {table.shape[1]} columns of data for {len(names)} fields")
        xyz = table[:, [names.index(f) for f in "xyz"]]
    elif mode == "binary":
        dt = np.dtype(cols)
        if len(raw) - offset < n * dt.itemsize:
            raise MapFileError(f"{p}: truncated binary PCD ({len(raw) - offset} bytes for {n} points of {dt.itemsize})")
        rec = np.frombuffer(raw, dtype=dt, count=n, offset=offset)
        xyz = np.stack([rec[f].astype(np.float64) for f in "xyz"], axis=-1)
    else:
        raise MapFileError(f"{p}: PCD DATA {mode!r} is not supported (use ascii or binary)")
    return xyz[np.all(np.isfinite(xyz), axis=1)]


def cloud_to_grid(points: np.ndarray, resolution: float, min_height: float, max_height: float,
                  padding: float = 0.5, frame_id: str = "map") -> OccupancyGridMap:
    """Points with ``min_height <= z <= max_height`` mark their cells occupied; every other cell
    of the cloud's footprint (plus ``padding`` m) is free."""
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"grid_resolution: expected > 0 m, got {resolution}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise ValueError(f"point cloud map: expected (N, 3) points, got shape {pts.shape}")
    lo = pts[:, :2].min(axis=0) - padding
    hi = pts[:, :2].max(axis=0) + padding
    cols, rows = (np.ceil((hi - lo) / resolution).astype(int) + 1).tolist()
    if rows * cols > 50_000_000:
        raise ValueError(f"point cloud map: {cols} x {rows} cells at {resolution} m is too large; use a coarser grid_resolution")
    data = np.full((rows, cols), FREE, dtype=np.int8)
    band = pts[(pts[:, 2] >= min_height) & (pts[:, 2] <= max_height)]
    ij = np.floor((band[:, :2] - lo) / resolution).astype(int)
    data[ij[:, 1], ij[:, 0]] = OCCUPIED
    return OccupancyGridMap(data=data, resolution=resolution, origin=(float(lo[0]), float(lo[1]), 0.0), frame_id=frame_id)
