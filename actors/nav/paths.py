"""Paths on disk and paths recorded while driving.

CSV layout: a header row ``x,y,yaw`` then one pose per row (metres, radians). A file with only
``x,y`` columns loads with yaw pointing along the path. :class:`PathRecorder` keeps a driven
path compact by storing a pose only after the robot moved or turned enough.
"""
from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from emos.errors import EmosError
from emos.geometry import wrap_angle

__all__ = ["PathFileError", "save_path_csv", "load_path_csv", "PathRecorder", "headings_along", "path_ahead"]

_HEADER = ("x", "y", "yaw")


class PathFileError(EmosError, ValueError):
    """A path CSV that is missing, has a bad header or a bad row."""


def headings_along(xy: np.ndarray) -> np.ndarray:
    """Yaw of each point facing the next one (the last point repeats the previous heading)."""
    p = np.asarray(xy, dtype=np.float64)
    if len(p) < 2:
        return np.zeros(len(p))
    d = np.diff(p[:, :2], axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    return np.r_[yaw, yaw[-1]]


def path_ahead(path: np.ndarray, xy: np.ndarray, max_offset: float) -> np.ndarray | None:
    """The part of ``path`` ((N, 2+) points) from its point nearest ``xy`` to its end, or None
    when ``xy`` is farther than ``max_offset`` m from every point (the robot has left it)."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) == 0:
        return None
    d = np.hypot(p[:, 0] - xy[0], p[:, 1] - xy[1])
    nearest = int(np.argmin(d))
    return p[nearest:] if d[nearest] <= max_offset else None


def save_path_csv(path: np.ndarray, file: str | os.PathLike) -> Path:
    """Write an (N, 3) [x, y, yaw] or (N, 2) [x, y] path with a header row."""
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"save_path_csv: expected an (N, 2) or (N, 3) path, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("save_path_csv: path contains NaN or inf")
    if p.shape[1] == 2:
        p = np.column_stack((p, headings_along(p)))
    out = Path(file)
    out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(_HEADER)
    # repr-precision floats so a save/load round trip is exact.
    writer.writerows([[repr(float(v)) for v in row] for row in p])
    out.write_text(buf.getvalue())
    return out


def load_path_csv(file: str | os.PathLike) -> np.ndarray:
    """Read a path CSV into an (N, 3) array; errors name the file, line and problem."""
    src = Path(file)
    try:
        text = src.read_text()
    except OSError as exc:
        raise PathFileError(f"cannot read path file {src}: {exc.strerror or exc}") from exc
    # (1-based line number, cells) of each non-blank line, so errors can name the line.
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(io.StringIO(text))) if r and any(c.strip() for c in r)]
    if not rows:
        raise PathFileError(f"{src}: empty file, expected a header row 'x,y,yaw'")
    line, header = rows[0]
    names = tuple(c.strip().lower() for c in header)
    if names not in (_HEADER, _HEADER[:2]):
        raise PathFileError(f"{src}:{line}: header must be 'x,y,yaw' or 'x,y', got {','.join(header)!r}")
    n_cols = len(names)
    values = np.empty((len(rows) - 1, n_cols))
    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != n_cols:
            raise PathFileError(f"{src}:{line}: expected {n_cols} values ({','.join(names)}), got {len(row)}: {row}")
        try:
            vals = [float(c) for c in row]
        except ValueError:
            raise PathFileError(f"{src}:{line}: non-numeric value in {row}") from None
        if not all(math.isfinite(v) for v in vals):
            raise PathFileError(f"{src}:{line}: NaN or inf in {row}")
        values[k] = vals
    if n_cols == 2:
        values = np.column_stack((values, headings_along(values)))
    return values


class PathRecorder:
    """Record a driven path from a stream of poses.

    Two filters decide whether an offered pose is kept (the first pose always is):

    - spatial: the robot moved at least ``min_distance`` metres or turned at least
      ``min_angle`` radians since the last kept pose (so standing still records nothing);
    - temporal, when ``recording_time_step`` is set (the spec's planner service parameter):
      at least that many seconds passed since the last kept pose, by the poses' stamps.

    :meth:`path` can append the latest pose so the recording ends where the robot stopped.
    """

    def __init__(
        self, min_distance: float = 0.1, min_angle: float = 0.2, recording_time_step: float | None = None
    ) -> None:
        if not (math.isfinite(min_distance) and min_distance >= 0):
            raise ValueError(f"PathRecorder.min_distance: expected >= 0 m, got {min_distance!r}")
        if not (math.isfinite(min_angle) and min_angle >= 0):
            raise ValueError(f"PathRecorder.min_angle: expected >= 0 rad, got {min_angle!r}")
        if recording_time_step is not None and not (math.isfinite(recording_time_step) and recording_time_step > 0):
            raise ValueError(f"PathRecorder.recording_time_step: expected > 0 s or None, got {recording_time_step!r}")
        self.min_distance = float(min_distance)
        self.min_angle = float(min_angle)
        self.recording_time_step = None if recording_time_step is None else float(recording_time_step)
        self._kept: list[tuple[float, float, float]] = []
        self._last_stamp: float | None = None
        self._latest: tuple[float, float, float] | None = None

    def __len__(self) -> int:
        return len(self._kept)

    def add(self, x: float, y: float, yaw: float, stamp: float | None = None) -> bool:
        """Offer one pose (``stamp`` in seconds, required with ``recording_time_step``);
        returns True if it was kept. Non-finite poses raise ``ValueError``."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            raise ValueError(f"PathRecorder.add: expected a finite pose, got ({x}, {y}, {yaw})")
        if self.recording_time_step is not None and (stamp is None or not math.isfinite(stamp)):
            raise ValueError("PathRecorder.add: a finite stamp (s) is required when recording_time_step is set")
        pose = (float(x), float(y), float(yaw))
        self._latest = pose
        if self._kept:
            lx, ly, lyaw = self._kept[-1]
            moved = math.hypot(x - lx, y - ly)
            turned = abs(wrap_angle(yaw - lyaw))
            if moved < self.min_distance and turned < self.min_angle:
                return False
            # stamp is never None here when recording_time_step is set (checked above).
            if (self.recording_time_step is not None and self._last_stamp is not None and stamp is not None
                    and stamp - self._last_stamp < self.recording_time_step):
                return False
        self._kept.append(pose)
        self._last_stamp = stamp
        return True

    def add_many(self, poses: np.ndarray, stamps: np.ndarray | None = None) -> int:
        """Offer an (N, 3) batch of poses in order (with N stamps if timed); returns how many were kept."""
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if stamps is None:
            return sum(self.add(*row) for row in p)
        t = np.asarray(stamps, dtype=np.float64).reshape(-1)
        if len(t) != len(p):
            raise ValueError(f"PathRecorder.add_many: {len(p)} poses but {len(t)} stamps")
        return sum(self.add(x, y, yaw, stamp=float(ts)) for (x, y, yaw), ts in zip(p, t))

    def path(self, include_latest: bool = True) -> np.ndarray:
        """The recorded (N, 3) path; with ``include_latest`` the last offered pose closes it."""
        kept = list(self._kept)
        if include_latest and self._latest is not None and kept and kept[-1] != self._latest:
            kept.append(self._latest)
        return np.array(kept, dtype=np.float64).reshape(-1, 3)

    def clear(self) -> None:
        self._kept.clear()
        self._latest = None
        self._last_stamp = None

    def save(self, file: str | os.PathLike) -> Path:
        return save_path_csv(self.path(), file)
