"""Read the BARN worlds straight from a clone of the official repository
(https://github.com/Daffan/the-barn-challenge), all 300 of them.

Layout: ``jackal_helper/worlds/BARN/world_<i>.world`` (Gazebo SDF: the obstacles are static
models with a ``<cylinder>`` collision geometry, placed by the model's ``<pose>``) and
``jackal_helper/worlds/BARN/path_files/path_<i>.npy`` (the reference path as (row, column)
cells of the 0.15 m grid the world was generated from). ``PATH`` may be the repository root or
the folder holding the ``world_<i>.world`` files.

The reference path length is computed as the challenge's ``run.py`` does: the path cells
converted to world coordinates, preceded by the start and followed by the goal.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .barn_worlds import BARN_CYLINDER_RADIUS, BARN_GOAL, BARN_START, BarnWorld

WORLD_SUBDIR = Path("jackal_helper") / "worlds" / "BARN"
_WORLD_NAME = re.compile(r"world_(\d+)\.world$")


def barn_world_dir(root: str | Path) -> Path:
    """The folder of ``world_<i>.world`` files in a repository clone (or that folder itself)."""
    root = Path(root).expanduser()
    for candidate in (root / WORLD_SUBDIR, root):
        if candidate.is_dir() and any(candidate.glob("world_*.world")):
            return candidate
    raise FileNotFoundError(f"--barn-repo {root}: no world_<i>.world files in {root / WORLD_SUBDIR} or {root} "
                            "(expected a clone of github.com/Daffan/the-barn-challenge)")


def path_cell_to_world(cells: np.ndarray) -> np.ndarray:
    """Path-file cells (row, column) to world metres (the conversion of the challenge's run.py:
    0.15 m cells, the grid's corner at x = -0.075 - 30 * 0.15, y = 5.075)."""
    r = BARN_CYLINDER_RADIUS
    cells = np.asarray(cells, dtype=float).reshape(-1, 2)
    return np.c_[cells[:, 0] * 2 * r - r - 30 * 2 * r, cells[:, 1] * 2 * r + r + 5]


def reference_path_length(cells: np.ndarray, start: tuple[float, ...] = BARN_START,
                          goal: tuple[float, float] = BARN_GOAL) -> float:
    poly = np.vstack([np.asarray(start[:2], dtype=float), path_cell_to_world(cells), np.asarray(goal, dtype=float)])
    return float(np.linalg.norm(np.diff(poly, axis=0), axis=1).sum())


def parse_world_file(path: str | Path) -> np.ndarray:
    """(N, 2) centres of the cylinder obstacles of a BARN ``.world`` file."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"BARN world file {path}: not valid SDF/XML ({exc})") from exc
    centres = []
    for model in root.iter("model"):
        cylinder = model.find("./link/collision/geometry/cylinder")
        if cylinder is None:
            continue  # the ground plane, lights, anything that is not an obstacle post
        name = model.get("name", "?")
        radius = cylinder.findtext("radius")
        if radius is None or abs(float(radius) - BARN_CYLINDER_RADIUS) > 1e-4:
            raise ValueError(f"BARN world file {path}: model {name!r} has cylinder radius {radius!r}; the BARN "
                             f"worlds use {BARN_CYLINDER_RADIUS} m")
        pose = model.findtext("pose")
        try:
            x, y = (float(v) for v in (pose or "").split()[:2])
        except ValueError:
            raise ValueError(f"BARN world file {path}: model {name!r} needs <pose>x y z r p y</pose>, got {pose!r}") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"BARN world file {path}: model {name!r} has a non-finite pose {pose!r}")
        centres.append((x, y))
    if not centres:
        raise ValueError(f"BARN world file {path}: no cylinder obstacles found")
    return np.asarray(centres, dtype=float)


def load_barn_repo(root: str | Path) -> dict[int, BarnWorld]:
    """Every world of a repository clone that has both its world file and its path file."""
    folder = barn_world_dir(root)
    worlds: dict[int, BarnWorld] = {}
    missing_paths = []
    for world_file in folder.glob("world_*.world"):
        m = _WORLD_NAME.search(world_file.name)
        if not m:
            continue
        idx = int(m.group(1))
        path_file = folder / "path_files" / f"path_{idx}.npy"
        if not path_file.is_file():
            missing_paths.append(idx)
            continue
        try:
            cells = np.load(path_file, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"BARN path file {path_file}: cannot read it as a .npy array ({exc})") from exc
        if cells.ndim != 2 or cells.shape[1] != 2 or len(cells) == 0:
            raise ValueError(f"BARN path file {path_file}: expected an (N, 2) array of path cells, got shape {cells.shape}")
        worlds[idx] = BarnWorld(idx, parse_world_file(world_file), reference_path_length(cells))
    if missing_paths:
        raise FileNotFoundError(f"--barn-repo {root}: no path_files/path_<i>.npy for world(s) {sorted(missing_paths)} "
                                f"in {folder}")
    if not worlds:
        raise FileNotFoundError(f"--barn-repo {root}: no world_<i>.world files in {folder}")
    return dict(sorted(worlds.items()))
