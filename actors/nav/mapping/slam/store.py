"""A saved pose graph: what the Mapper's ``save_map`` writes beside the YAML + PGM, and what its
localization-only mode loads to localize against.

``NAME.posegraph.npz`` (numpy's zip of plain arrays, read with ``allow_pickle=False``: a file
is untrusted input and must never run code): every node's optimised pose and its scan (ranges
and beam angles, concatenated, with each scan's beam count), and the likelihood field's
parameters. It holds the scans rather than a rendered map so that a localizer matches against
the same hits, at the same resolution, that the SLAM built its graph from (a PGM has lost them
to 5 cm cells and a probability threshold).
"""
from __future__ import annotations

import os
from pathlib import Path

import attrs
import numpy as np

from emos.errors import EmosError

__all__ = ["PoseGraphFile", "PoseGraphFileError", "load_posegraph", "save_posegraph", "POSEGRAPH_SUFFIX"]

POSEGRAPH_SUFFIX = ".posegraph.npz"
_VERSION = 1
_MAX_BEAMS = 100_000  # per scan: a bigger count is a corrupt or hostile file, not a lidar


class PoseGraphFileError(EmosError, ValueError):
    """A pose-graph file that cannot be read or does not hold what it should."""


@attrs.define(frozen=True, eq=False)
class PoseGraphFile:
    """``poses`` (N, 3) map frame; ``ranges[i]``, ``angles[i]`` the scan of node ``i`` (NaN/inf
    kept: no echo); ``resolution``, ``sigma``, ``max_range``, ``min_range`` of the SLAM that
    built it."""

    poses: np.ndarray
    ranges: list[np.ndarray]
    angles: list[np.ndarray]
    resolution: float
    sigma: float
    max_range: float
    min_range: float


def save_posegraph(path: str | os.PathLike, poses: np.ndarray, scans: list[tuple[np.ndarray, np.ndarray]], *,
                   resolution: float, sigma: float, max_range: float, min_range: float) -> Path:
    """Write ``poses`` (N, 3) and their ``scans`` ((ranges, angles) each) to ``path``."""
    p = Path(path)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(poses) != len(scans):
        raise ValueError(f"save_posegraph {p}: {len(poses)} poses for {len(scans)} scans")
    counts = np.array([np.asarray(r).size for r, _ in scans], dtype=np.int64)
    for k, (r, a) in enumerate(scans):
        if np.asarray(r).size != np.asarray(a).size:
            raise ValueError(f"save_posegraph {p}: scan {k} has {np.asarray(r).size} ranges for "
                             f"{np.asarray(a).size} angles")

    def cat(xs: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in xs]) if xs else np.zeros(0)

    tmp = p.with_name(p.name + ".tmp.npz")
    np.savez_compressed(tmp, version=np.array(_VERSION), poses=poses, counts=counts,
                        ranges=cat([r for r, _ in scans]), angles=cat([a for _, a in scans]),
                        field=np.array([resolution, sigma, max_range, min_range], dtype=np.float64))
    os.replace(tmp, p)  # a reader never sees half a file
    return p


def load_posegraph(path: str | os.PathLike) -> PoseGraphFile:
    """Read and check a file of :func:`save_posegraph`; :class:`PoseGraphFileError` naming the
    file and what was expected otherwise."""
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in ("version", "poses", "counts", "ranges", "angles", "field")}
    except KeyError as exc:
        raise PoseGraphFileError(f"{p}: not a pose-graph file: missing array {exc}") from exc
    except (OSError, ValueError) as exc:
        raise PoseGraphFileError(f"{p}: cannot read a pose-graph file ({exc})") from exc
    if int(data["version"]) != _VERSION:
        raise PoseGraphFileError(f"{p}: pose-graph format version {int(data['version'])}, expected {_VERSION}")
    poses = np.asarray(data["poses"], dtype=np.float64)
    counts = np.asarray(data["counts"])
    ranges = np.asarray(data["ranges"], dtype=np.float64).ravel()
    angles = np.asarray(data["angles"], dtype=np.float64).ravel()
    fld = np.asarray(data["field"], dtype=np.float64).ravel()
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) == 0 or not np.isfinite(poses).all():
        raise PoseGraphFileError(f"{p}: 'poses' must be a non-empty (N, 3) array of finite numbers, got shape "
                                 f"{poses.shape}")
    if counts.shape != (len(poses),) or counts.dtype.kind not in "iu" or (counts < 0).any() or (counts > _MAX_BEAMS).any():
        raise PoseGraphFileError(f"{p}: 'counts' must hold one beam count (0..{_MAX_BEAMS}) per pose ({len(poses)})")
    if ranges.size != int(counts.sum()) or angles.size != ranges.size or not np.isfinite(angles).all():
        raise PoseGraphFileError(f"{p}: {ranges.size} ranges and {angles.size} angles for {int(counts.sum())} beams; "
                                 "expected equal counts and finite angles")
    if fld.size != 4 or not np.isfinite(fld).all() or fld[0] <= 0 or fld[1] <= 0 or fld[2] <= 0 or fld[3] < 0:
        raise PoseGraphFileError(f"{p}: 'field' must be [resolution > 0, sigma > 0, max_range > 0, min_range >= 0], "
                                 f"got {fld.tolist()}")
    edges = np.concatenate([[0], np.cumsum(counts)])
    return PoseGraphFile(poses=poses, ranges=[ranges[edges[k]:edges[k + 1]] for k in range(len(poses))],
                         angles=[angles[edges[k]:edges[k + 1]] for k in range(len(poses))],
                         resolution=float(fld[0]), sigma=float(fld[1]), max_range=float(fld[2]), min_range=float(fld[3]))
