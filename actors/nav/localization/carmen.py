"""Reading CARMEN log files (the Radish format): laser scans with their poses, and odometry.

Lines are space separated; the first word is the message type. Two are read:

- ``FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``:
  one scan of ``n`` ranges (m), the beams spread over 180 degrees counter-clockwise from
  -90 degrees (the robot's right), and the robot's pose when it was taken.
- ``ODOM x y theta tv rv accel timestamp host logger_timestamp``: a robot pose.

Every other type (``PARAM``, ``NEFF``, ``SYNC``, ``RLASER``, comments) is skipped silently.
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
from collections.abc import Iterator
from pathlib import Path

import attrs
import numpy as np

from emos.errors import EmosError
from emos.ratelimit import RateLimitedLog

__all__ = ["CarmenScan", "CarmenLog", "CarmenLogError", "read_carmen", "beam_angles"]

_log = logging.getLogger("emos.nav.localization.carmen")


class CarmenLogError(EmosError, ValueError):
    """A CARMEN log that cannot be used at all (missing, unreadable, or without one valid scan)."""


@attrs.define(frozen=True, eq=False)
class CarmenScan:
    """One ``FLASER`` line: ranges (m), the pose it gives (x, y, theta) and its timestamp (s)."""

    ranges: np.ndarray
    pose: np.ndarray
    timestamp: float
    line: int


@attrs.define(eq=False)
class CarmenLog:
    """What a log holds: its scans in order, its ODOM poses (N, 4: t, x, y, theta), and how many
    lines of the read types were skipped as malformed."""

    path: str
    scans: list[CarmenScan]
    odometry: np.ndarray
    skipped: int

    @property
    def poses(self) -> np.ndarray:
        """(N, 3) pose of every scan: in the Radish "corrected" logs, the reference trajectory."""
        return np.array([s.pose for s in self.scans], dtype=np.float64).reshape(-1, 3)

    @property
    def name(self) -> str:
        base = os.path.basename(self.path)
        for suffix in (".gz", ".log", ".clf"):
            base = base[: -len(suffix)] if base.endswith(suffix) else base
        return base


def beam_angles(n: int) -> np.ndarray:
    """Angles (rad, robot frame) of the ``n`` beams of a CARMEN front laser: 180 degrees from
    -90 degrees, counter-clockwise. Logs store 180 (1 degree apart, the last at 89), 181 or 361
    beams (both ends included): an odd count includes both ends, an even one does not."""
    if n < 2:
        raise ValueError(f"beam_angles: expected at least 2 beams, got {n}")
    step = math.pi / (n - 1) if n % 2 == 1 else math.pi / n
    return -math.pi / 2.0 + step * np.arange(n)


def _floats(words: list[str]) -> list[float]:
    out = [float(w) for w in words]  # ValueError on a word that is not a number
    if not all(math.isfinite(v) for v in out):
        raise ValueError("a value is not finite")
    return out


def _parse_flaser(words: list[str], line: int) -> CarmenScan:
    if len(words) < 2:
        raise ValueError("no beam count")
    n = int(words[1])
    if not 2 <= n <= 100_000:
        raise ValueError(f"beam count {n} out of range [2, 100000]")
    # n ranges, 6 pose values and the timestamp; host and logger timestamp may be missing.
    if len(words) < 2 + n + 7:
        raise ValueError(f"{len(words) - 2} values after the count, expected {n} ranges + 7")
    ranges = np.array(_floats(words[2 : 2 + n]), dtype=np.float64)
    if (ranges < 0).any():
        raise ValueError("a negative range")
    x, y, th = _floats(words[2 + n : 5 + n])
    stamp = _floats([words[8 + n]])[0]
    return CarmenScan(ranges=ranges, pose=np.array([x, y, th]), timestamp=stamp, line=line)


def _parse_odom(words: list[str]) -> list[float]:
    if len(words) < 8:
        raise ValueError(f"{len(words) - 1} values, expected at least 7")
    x, y, th = _floats(words[1:4])
    stamp = _floats([words[7]])[0]
    return [stamp, x, y, th]


def _lines(path: Path) -> Iterator[str]:
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8", errors="replace") as fh:
        yield from fh


def read_carmen(path: str | os.PathLike[str], *, report: RateLimitedLog | None = None,
                logger: logging.Logger | None = None) -> CarmenLog:
    """Read a CARMEN log (see the module docstring). Raises CarmenLogError naming the file when
    it cannot be read or holds no valid FLASER line."""
    p = Path(path)
    report = report or RateLimitedLog(interval=5.0)
    logger = logger or _log
    scans: list[CarmenScan] = []
    odom: list[list[float]] = []
    skipped = 0
    try:
        for number, text in enumerate(_lines(p), start=1):
            words = text.split()
            if not words or words[0] not in ("FLASER", "ODOM"):
                continue
            try:
                if words[0] == "FLASER":
                    scans.append(_parse_flaser(words, number))
                else:
                    odom.append(_parse_odom(words))
            except (ValueError, IndexError) as exc:
                skipped += 1
                report.warning(("carmen", str(p)), "CARMEN log %s line %d: skipping a malformed %s line (%s)",
                               p, number, words[0], exc, logger=logger)
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise CarmenLogError(f"CARMEN log {p}: cannot read it: {exc}") from exc
    if not scans:
        raise CarmenLogError(f"CARMEN log {p}: no valid FLASER line (skipped {skipped} malformed lines)")
    if skipped:
        logger.warning("CARMEN log %s: %d malformed FLASER/ODOM lines skipped in all", p, skipped)
    return CarmenLog(path=str(p), scans=scans, odometry=np.array(odom, dtype=np.float64).reshape(-1, 4), skipped=skipped)
