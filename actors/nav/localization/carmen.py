"""Reading CARMEN log files (the Radish format): laser scans with their poses, and odometry.

Lines are space separated; the first word is the message type. The front laser is logged in one
of three forms; a log is read from the first of them it holds, in this order (a log written by
a newer logger can hold the same scans twice, as ``ROBOTLASER1`` and ``RAWLASER1``):

- ``FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``
  (the old form, and the Radish "corrected" logs'): ``x y theta`` is the laser's pose. The beams
  spread counter-clockwise over the field of view of ``PARAM laser_front_laser_fov`` (180 degrees
  when the log does not give it), from its right end (see :func:`beam_angles`).
- ``ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r_1 ... r_n
  m e_1 ... e_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv forward_safety
  side_safety turn_axis timestamp host logger_timestamp``: beam k at ``start_angle + k *
  resolution``; the laser's pose is the scan's pose.
- ``RAWLASER1 type start_angle fov resolution max_range accuracy remission_mode n r_1 ... r_n
  m e_1 ... e_m timestamp host logger_timestamp``: no pose of its own, so the scan's pose is the
  ``ODOM`` trajectory interpolated at its timestamp and moved forward by ``PARAM
  robot_frontlaser_offset``; a scan outside the trajectory's time span is skipped and counted.

``ODOM x y theta tv rv accel timestamp host logger_timestamp`` is a robot pose. From ``PARAM name
value ...`` the reader takes ``laser_front_laser_fov`` (radians up to 2 pi, degrees above; a
value printed within 0.01 degrees of a whole degree is that degree), ``robot_front_laser_max``
(the front laser's range, m: the ``max_range`` of FLASER scans) and ``robot_frontlaser_offset``.
Every other type (``NEFF``, ``SYNC``, ``RLASER``, ``ROBOTLASER2``, other lasers, comments) is
skipped silently.

A line of a read type that is malformed (too few fields, a count that does not match, a value
that is not a finite number, a negative range) is skipped, counted, and reported through a
rate-limited log naming the file and line: a log of 10 000 lines with one torn line is read,
not refused. ``.gz`` files are read through gzip.
"""
from __future__ import annotations

import gzip
import logging
import math
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from emos.errors import EmosError
from emos.geometry import wrap_angle
from emos.ratelimit import RateLimitedLog

__all__ = ["CarmenScan", "CarmenLog", "CarmenLogError", "read_carmen", "beam_angles", "carmen_stem", "is_carmen", "LASER_FORMS",
           "CARMEN_SUFFIXES"]

_log = logging.getLogger("emos.nav.localization.carmen")

#: How CARMEN log files are named (gzip-compressed or not).
CARMEN_SUFFIXES = (".log", ".log.gz", ".clf", ".clf.gz")
#: The front laser's message types, in the order a log is read from.
LASER_FORMS = ("FLASER", "ROBOTLASER1", "RAWLASER1")
_MAX_BEAMS = 100_000
#: Readings this far (m) or farther are "no echo" unless a log's laser declares a shorter range.
DEFAULT_NO_ECHO_RANGE = 30.0


class CarmenLogError(EmosError, ValueError):
    """A CARMEN log that cannot be used at all (missing, unreadable, or without one valid scan)."""


@attrs.define(frozen=True, eq=False)
class CarmenScan:
    """One front-laser scan: ranges (m), the beams' angles in the laser's frame (rad), the
    laser's pose (x, y, theta), its timestamp (s), the line it came from, and the laser's range
    (m; ``inf`` when the log does not say)."""

    ranges: np.ndarray
    pose: np.ndarray
    timestamp: float
    line: int
    angles: np.ndarray
    max_range: float = math.inf


@attrs.define(eq=False)
class CarmenLog:
    """What a log holds: its scans in order, its ODOM poses (N, 4: t, x, y, theta), how many
    lines of the read types were skipped as malformed, and which message type the scans came
    from (one of :data:`LASER_FORMS`)."""

    path: str
    scans: list[CarmenScan]
    odometry: np.ndarray
    skipped: int
    laser: str = "FLASER"

    @property
    def poses(self) -> np.ndarray:
        """(N, 3) pose of every scan: in the Radish "corrected" logs, the reference trajectory."""
        return np.array([s.pose for s in self.scans], dtype=np.float64).reshape(-1, 3)

    @property
    def max_range(self) -> float:
        """The shortest laser range any scan declares (m); ``inf`` when the log gives none."""
        return min((s.max_range for s in self.scans), default=math.inf)

    def no_echo_range(self, limit: float | None = None) -> float:
        """The range (m) at and beyond which a reading counts as "no echo": ``limit`` (30 m when
        not given), or the laser's own range when the log declares a shorter one (lasers report
        a missing echo as their maximum range)."""
        return min(DEFAULT_NO_ECHO_RANGE if limit is None else float(limit), self.max_range)

    @property
    def name(self) -> str:
        return os.path.basename(carmen_stem(self.path))


def carmen_stem(path: str | os.PathLike[str]) -> str:
    """``path`` without its CARMEN suffix (``.log.gz``, ``.clf``, ...; a bare ``.gz`` too)."""
    text = str(path)
    suffix = next((x for x in CARMEN_SUFFIXES if text.lower().endswith(x)), ".gz" if text.endswith(".gz") else "")
    return text[: len(text) - len(suffix)]


def is_carmen(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is named like a CARMEN log."""
    return str(path).lower().endswith(CARMEN_SUFFIXES)


def beam_angles(n: int, fov: float = math.pi) -> np.ndarray:
    """Angles (rad, laser frame) of the ``n`` beams of a CARMEN ``FLASER`` scan over ``fov``
    (rad), counter-clockwise from its right end. Logs store 180 beams over 180 degrees (1 degree
    apart, the last at 89), 181 or 361 (both ends included): an odd count includes both ends, an
    even one does not."""
    if n < 2:
        raise ValueError(f"beam_angles: expected at least 2 beams, got {n}")
    if not (math.isfinite(fov) and 0.0 < fov <= 2.0 * math.pi + 1e-9):
        raise ValueError(f"beam_angles: expected a field of view in (0, 2 pi] rad, got {fov}")
    step = fov / (n - 1) if n % 2 == 1 else fov / n
    return -fov / 2.0 + step * np.arange(n)


def _floats(words: list[str]) -> list[float]:
    out = [float(w) for w in words]  # ValueError on a word that is not a number
    if not all(math.isfinite(v) for v in out):
        raise ValueError("a value is not finite")
    return out


def _ranges(words: list[str]) -> np.ndarray:
    ranges = np.array(_floats(words), dtype=np.float64)
    if (ranges < 0).any():
        raise ValueError("a negative range")
    return ranges


def _count(word: str, what: str) -> int:
    n = int(word)
    if not 0 <= n <= _MAX_BEAMS:
        raise ValueError(f"{what} {n} out of range [0, {_MAX_BEAMS}]")
    return n


@attrs.define(frozen=True)
class _Flaser:
    ranges: np.ndarray
    pose: np.ndarray
    timestamp: float
    line: int


def _parse_flaser(words: list[str], line: int) -> _Flaser:
    if len(words) < 2:
        raise ValueError("no beam count")
    n = _count(words[1], "beam count")
    if n < 2:
        raise ValueError(f"beam count {n} out of range [2, {_MAX_BEAMS}]")
    # n ranges, 6 pose values and the timestamp; host and logger timestamp may be missing.
    if len(words) < 2 + n + 7:
        raise ValueError(f"{len(words) - 2} values after the count, expected {n} ranges + 7")
    ranges = _ranges(words[2 : 2 + n])
    x, y, th = _floats(words[2 + n : 5 + n])
    stamp = _floats([words[8 + n]])[0]
    return _Flaser(ranges=ranges, pose=np.array([x, y, th]), timestamp=stamp, line=line)


def _parse_laser_header(words: list[str]) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The part ROBOTLASER1 and RAWLASER1 share: beam angles, ranges, the laser's range, and the
    index of the first word after the remissions."""
    if len(words) < 9:
        raise ValueError(f"{len(words) - 1} values, expected at least 8 before the ranges")
    start, fov, resolution, max_range = _floats(words[2:6])
    n = _count(words[8], "beam count")
    if n < 2:
        raise ValueError(f"beam count {n} out of range [2, {_MAX_BEAMS}]")
    if not 0.0 < abs(resolution) * (n - 1) <= 2.0 * math.pi + 1e-6:
        raise ValueError(f"{n} beams {resolution} rad apart do not fit in one turn")
    if max_range <= 0.0:
        raise ValueError(f"maximum range {max_range} is not positive")
    if len(words) < 9 + n + 1:
        raise ValueError(f"{len(words) - 9} values after the beam count, expected {n} ranges and a remission count")
    ranges = _ranges(words[9 : 9 + n])
    m = _count(words[9 + n], "remission count")
    angles = start + resolution * np.arange(n)
    return angles, ranges, max_range, 10 + n + m


def _parse_robotlaser(words: list[str], line: int) -> CarmenScan:
    angles, ranges, max_range, i = _parse_laser_header(words)
    # the laser's pose, the robot's, tv, rv, two safety distances, turn axis, then the timestamp
    if len(words) < i + 12:
        raise ValueError(f"{len(words) - i} values after the remissions, expected 12")
    x, y, th = _floats(words[i : i + 3])
    stamp = _floats([words[i + 11]])[0]
    return CarmenScan(ranges=ranges, pose=np.array([x, y, th]), timestamp=stamp, line=line,
                      angles=angles, max_range=max_range)


def _parse_rawlaser(words: list[str], line: int) -> tuple[np.ndarray, np.ndarray, float, float, int]:
    angles, ranges, max_range, i = _parse_laser_header(words)
    if len(words) < i + 1:
        raise ValueError("no timestamp after the remissions")
    stamp = _floats([words[i]])[0]
    return angles, ranges, max_range, stamp, line


def _parse_odom(words: list[str]) -> list[float]:
    if len(words) < 8:
        raise ValueError(f"{len(words) - 1} values, expected at least 7")
    x, y, th = _floats(words[1:4])
    stamp = _floats([words[7]])[0]
    return [stamp, x, y, th]


def _fov_param(value: str) -> float:
    """``laser_front_laser_fov`` in radians: radians up to 2 pi, degrees above (loggers wrote
    both); a value printed within 0.01 degrees of a whole degree is that degree."""
    v = float(value)
    deg = math.degrees(v) if v <= 2.0 * math.pi * 1.0001 else v
    if abs(deg - round(deg)) < 0.01:
        deg = float(round(deg))
    if not (math.isfinite(deg) and 0.0 < deg <= 360.0):
        raise ValueError(f"field of view {value} is not in (0, 360] degrees")
    return math.pi * (deg / 180.0)


def _finite_param(value: str) -> float:
    return _floats([value])[0]


_PARAMS: dict[str, Callable[[str], float]] = {"laser_front_laser_fov": _fov_param, "robot_front_laser_max": _finite_param,
                                              "robot_frontlaser_offset": _finite_param}


def _lines(path: Path) -> Iterator[str]:
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8", errors="replace") as fh:
        yield from fh


def _interpolate_pose(odom: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """Poses (N, 3) of the ODOM trajectory (t, x, y, theta rows, in time order) at ``stamps``."""
    theta = np.unwrap(odom[:, 3])
    return np.stack([np.interp(stamps, odom[:, 0], odom[:, 1]), np.interp(stamps, odom[:, 0], odom[:, 2]),
                     wrap_angle(np.interp(stamps, odom[:, 0], theta))], axis=1)


def _flaser_scans(found: list[_Flaser], params: dict[str, float]) -> list[CarmenScan]:
    fov = params.get("laser_front_laser_fov", math.pi)
    max_range = params.get("robot_front_laser_max", math.inf)
    max_range = max_range if max_range > 0 else math.inf
    angles = {n: beam_angles(n, fov) for n in {len(f.ranges) for f in found}}  # one array per beam count
    return [CarmenScan(ranges=f.ranges, pose=f.pose, timestamp=f.timestamp, line=f.line, angles=angles[len(f.ranges)],
                       max_range=max_range) for f in found]


def _rawlaser_scans(found: list[tuple], odom: np.ndarray, params: dict[str, float], p: Path,
                    logger: logging.Logger) -> list[CarmenScan]:
    if len(odom) < 2:
        logger.warning("CARMEN log %s: %d RAWLASER1 scans but %d ODOM poses to place them by; none read",
                       p, len(found), len(odom))
        return []
    odom = odom[np.argsort(odom[:, 0], kind="stable")]
    stamps = np.array([f[3] for f in found])
    inside = (stamps >= odom[0, 0]) & (stamps <= odom[-1, 0])
    if not inside.all():
        logger.warning("CARMEN log %s: %d of %d RAWLASER1 scans lie outside the ODOM poses' time span "
                       "[%.3f, %.3f] s and are skipped", p, int((~inside).sum()), len(found), odom[0, 0], odom[-1, 0])
    poses = _interpolate_pose(odom, stamps[inside])
    offset = params.get("robot_frontlaser_offset", 0.0)
    poses[:, 0] += offset * np.cos(poses[:, 2])
    poses[:, 1] += offset * np.sin(poses[:, 2])
    kept = [f for f, ok in zip(found, inside) if ok]
    return [CarmenScan(ranges=f[1], pose=pose, timestamp=f[3], line=f[4], angles=f[0], max_range=f[2])
            for f, pose in zip(kept, poses)]


def read_carmen(path: str | os.PathLike[str], *, report: RateLimitedLog | None = None,
                logger: logging.Logger | None = None) -> CarmenLog:
    """Read a CARMEN log (see the module docstring). Raises CarmenLogError naming the file when
    it cannot be read or holds no valid front-laser scan."""
    p = Path(path)
    report = report or RateLimitedLog(interval=5.0)
    logger = logger or _log
    found: dict[str, list] = {form: [] for form in LASER_FORMS}
    parsers: dict[str, Callable[[list[str], int], Any]] = {"FLASER": _parse_flaser, "ROBOTLASER1": _parse_robotlaser, "RAWLASER1": _parse_rawlaser}
    odom: list[list[float]] = []
    params: dict[str, float] = {}
    skipped = 0
    try:
        for number, text in enumerate(_lines(p), start=1):
            words = text.split()
            if not words:
                continue
            kind = words[0]
            try:
                if kind in parsers:
                    found[kind].append(parsers[kind](words, number))
                elif kind == "ODOM":
                    odom.append(_parse_odom(words))
                elif kind == "PARAM" and len(words) >= 3 and words[1] in _PARAMS:
                    params[words[1]] = _PARAMS[words[1]](words[2])
            except (ValueError, IndexError) as exc:
                skipped += 1
                report.warning(("carmen", str(p)), "CARMEN log %s line %d: skipping a malformed %s line (%s)",
                               p, number, kind, exc, logger=logger)
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise CarmenLogError(f"CARMEN log {p}: cannot read it: {exc}") from exc
    odometry = np.array(odom, dtype=np.float64).reshape(-1, 4)
    form = next((f for f in LASER_FORMS if found[f]), None)
    scans: list[CarmenScan] = []
    if form == "FLASER":
        scans = _flaser_scans(found[form], params)
    elif form == "ROBOTLASER1":
        scans = found[form]
    elif form == "RAWLASER1":
        scans = _rawlaser_scans(found[form], odometry, params, p, logger)
    if form is None or not scans:
        raise CarmenLogError(f"CARMEN log {p}: no valid front-laser scan (expected {', '.join(LASER_FORMS)} lines; "
                             f"skipped {skipped} malformed lines)")
    others = [f"{len(found[f])} {f}" for f in LASER_FORMS if f != form and found[f]]
    if others:
        logger.info("CARMEN log %s: read the %d %s scans; %s lines not used (the same laser logged again)",
                    p, len(found[form]), form, ", ".join(others))
    if skipped:
        logger.warning("CARMEN log %s: %d malformed lines skipped in all", p, skipped)
    return CarmenLog(path=str(p), scans=scans, odometry=odometry, skipped=skipped, laser=form)
