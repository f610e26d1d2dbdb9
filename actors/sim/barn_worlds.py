"""The BARN world file: loading, index selection, and the challenge's constants."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import attrs
import numpy as np

# Frame, start, goal and rules from the BARN README shipped next to worlds.json.
BARN_START = (-2.25, 3.0, 1.57)
BARN_GOAL = (-2.25, 13.0)
BARN_GOAL_RADIUS = 1.0
BARN_TIME_LIMIT = 100.0
BARN_CYLINDER_RADIUS = 0.075
BARN_CYLINDER_HEIGHT = 1.0
BARN_TOP_SPEED = 2.0


@attrs.define(frozen=True, eq=False)
class BarnWorld:
    idx: int
    cylinders: np.ndarray  # (N, 2) centres, metres, world frame
    path_length: float

    def metric(self, success: bool, time_s: float) -> float:
        return barn_metric(success, time_s, self.path_length)


def barn_metric(success: bool, time_s: float, path_length: float, low: float = 2.0) -> float:
    """Official score of one run: success * T / clip(t, 2T, 8T) with T = path_length / 2 m/s.
    ``low=4`` is the 2022-23 rule (clip from 4T: best score 0.25)."""
    if not success:
        return 0.0
    optimal = path_length / BARN_TOP_SPEED
    return optimal / float(np.clip(time_s, low * optimal, 8 * optimal))


def repo_root() -> Path:
    """The EMOS repository root (three levels above this file: actors/sim/)."""
    return Path(__file__).resolve().parents[2]


def default_worlds_file() -> Path:
    """The 250 worlds shipped inside the package (``actors/sim/data/barn/worlds.json``)."""
    from .data.barn import PACKAGED_WORLDS

    return PACKAGED_WORLDS


def load_barn_worlds(path: str | Path | None = None) -> dict[int, BarnWorld]:
    """All worlds of a BARN source, by index: a world file (JSON, the packaged one when
    ``path`` is None) or a directory, read as a clone of the official repository (all 300
    worlds, see :mod:`emos.actors.sim.barn_repo`)."""
    path = Path(path).expanduser() if path is not None else default_worlds_file()
    if path.is_dir():
        from .barn_repo import load_barn_repo

        return load_barn_repo(path)
    if not path.is_file():
        raise FileNotFoundError(f"BARN world file not found: {path} (a worlds JSON file or a clone of the "
                                "BARN repository was expected)")
    # A Simulator's config check and its world builder both read the file; a BARN run's processes
    # are forked after the check, so they find it parsed (the 250 worlds take 0.1-0.4 s).
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _PARSED:
        _PARSED.clear()  # one file at a time is all a run reads
        _PARSED[key] = _parse_worlds_file(path)
    return dict(_PARSED[key])


_PARSED: dict[tuple[str, int, int], dict[int, BarnWorld]] = {}


def _parse_worlds_file(path: Path) -> dict[int, BarnWorld]:
    try:
        raw = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"BARN world file {path} is not valid JSON: {exc}") from exc
    if not isinstance(raw, dict) or not raw:
        raise ValueError(f"BARN world file {path}: expected a non-empty object of worlds by index")
    worlds = {}
    for key, entry in raw.items():
        try:
            idx = int(key)
            cyl = np.asarray(entry["cylinders"], dtype=float).reshape(-1, 2)
            length = float(entry["path_length"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"BARN world file {path}: world {key!r} needs 'cylinders' [[x, y], ...] "
                             f"and 'path_length' ({exc})") from exc
        if not (math.isfinite(length) and length > 0) or not np.all(np.isfinite(cyl)):
            raise ValueError(f"BARN world file {path}: world {key!r} has non-finite or non-positive values")
        cyl.setflags(write=False)  # shared by every caller of the cached result
        worlds[idx] = BarnWorld(idx, cyl, length)
    return dict(sorted(worlds.items()))


def parse_indices(spec: str) -> list[int]:
    """"1,2,5-9" -> [1, 2, 5, 6, 7, 8, 9] (order kept, duplicates dropped)."""
    out: list[int] = []
    for part in spec.split(","):
        part = part.strip()
        if not part:
            continue
        m = re.fullmatch(r"(\d+)\s*-\s*(\d+)|(\d+)", part)
        if not m:
            raise ValueError(f"bad world selection {part!r} in {spec!r}: expected N or N-M, comma separated")
        if m.group(3) is not None:
            values = [int(m.group(3))]
        else:
            a, b = int(m.group(1)), int(m.group(2))
            if b < a:
                raise ValueError(f"bad world range {part!r}: end before start")
            values = list(range(a, b + 1))
        out.extend(v for v in values if v not in out)
    if not out:
        raise ValueError(f"empty world selection {spec!r}")
    return out
