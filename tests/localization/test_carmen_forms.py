"""The CARMEN reader's other laser forms: ``ROBOTLASER1`` (its own angles, range and laser
pose), ``RAWLASER1`` (placed on the ODOM trajectory by its timestamp), ``FLASER`` with the
log's field-of-view and range parameters, and which form a log holding several is read from.
The benchmark gives the same answer on a real log whichever form it is written in."""
from __future__ import annotations

import gzip
import json
import logging
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emos.actors.nav.localization import CarmenLogError, beam_angles, read_carmen
from emos.ratelimit import RateLimitedLog
from tests.localization.helpers import ACES_LOG

pytestmark = pytest.mark.unit


def _robotlaser(ranges, start, res, laser_pose, robot_pose=(0.0, 0.0, 0.0), stamp=3.0, max_range=8.0,
                remissions=(0.5, 0.25)) -> str:
    n = len(ranges)
    words = ["ROBOTLASER1", "0", repr(start), repr(res * (n - 1)), repr(res), repr(max_range), "0.01", "0", str(n),
             *map(repr, ranges), str(len(remissions)), *map(repr, remissions), *map(repr, laser_pose),
             *map(repr, robot_pose), "0.3", "0.1", "0.2", "0.1", "0.0", repr(stamp), "host", repr(stamp)]
    return " ".join(words) + "\n"


def _rawlaser(ranges, start, res, stamp, max_range=8.0) -> str:
    n = len(ranges)
    return " ".join(["RAWLASER1", "0", repr(start), repr(res * (n - 1)), repr(res), repr(max_range), "0.01", "0",
                     str(n), *map(repr, ranges), "0", repr(stamp), "host", repr(stamp)]) + "\n"


def _odom(x, y, th, stamp) -> str:
    return f"ODOM {x!r} {y!r} {th!r} 0 0 0 {stamp!r} host {stamp!r}\n"


def _flaser(ranges, pose, stamp) -> str:
    p = " ".join(map(repr, pose))
    return f"FLASER {len(ranges)} {' '.join(map(repr, ranges))} {p} {p} {stamp!r} host {stamp!r}\n"


def _write(path: Path, lines: list[str]) -> Path:
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "wt") as fh:
        fh.writelines(lines)
    return path


def test_robotlaser_scans_carry_their_own_angles_range_and_the_laser_pose(tmp_path):
    # A 270 degree laser, 0.5 degrees apart, mounted 0.2 m ahead of the robot's centre.
    res, start = math.radians(0.5), math.radians(-135.0)
    ranges = [1.0 + 0.01 * k for k in range(541)]
    robot = (1.0, 2.0, math.pi / 2)
    laser = (1.0, 2.2, math.pi / 2)
    path = _write(tmp_path / "robot.log", ["PARAM laser_front_laser_fov 180 host 0\n",
                                           _robotlaser(ranges, start, res, laser, robot, stamp=7.5)])
    log = read_carmen(path)
    assert log.laser == "ROBOTLASER1" and len(log.scans) == 1 and log.skipped == 0
    scan = log.scans[0]
    assert scan.ranges.tolist() == ranges, "the remissions are not read as ranges"
    assert scan.angles[0] == pytest.approx(start) and scan.angles[-1] == pytest.approx(math.radians(135.0))
    assert np.allclose(np.diff(scan.angles), res), "the FLASER field-of-view parameter does not apply to it"
    assert scan.pose.tolist() == list(laser) and scan.timestamp == 7.5 and scan.max_range == 8.0
    assert log.max_range == 8.0
    assert log.no_echo_range() == 8.0 and log.no_echo_range(5.0) == 5.0, "a shorter laser range wins over 30 m"


def test_rawlaser_scans_are_placed_on_the_odometry_by_their_timestamp(tmp_path, caplog):
    res, start = math.radians(1.0), -math.pi / 2
    ranges = [2.0] * 181
    lines = ["PARAM robot_frontlaser_offset 0.1 host 0\n",
             _odom(0.0, 0.0, math.pi - 0.1, 10.0), _odom(1.0, 0.0, -math.pi + 0.1, 12.0),  # through +-pi
             _rawlaser(ranges, start, res, 11.0), _rawlaser(ranges, start, res, 11.5),
             _rawlaser(ranges, start, res, 20.0)]  # after the last ODOM pose: no pose for it
    path = _write(tmp_path / "raw.log.gz", lines)
    with caplog.at_level(logging.WARNING, logger="emos.nav.localization.carmen"):
        log = read_carmen(path)
    assert log.laser == "RAWLASER1" and [s.timestamp for s in log.scans] == [11.0, 11.5]
    first = log.scans[0]
    # halfway in time: x 0.5, heading pi (the short way round, not through 0), the laser 0.1 m ahead
    assert first.pose[2] == pytest.approx(math.pi) or first.pose[2] == pytest.approx(-math.pi)
    assert first.pose[0] == pytest.approx(0.5 - 0.1) and first.pose[1] == pytest.approx(0.0, abs=1e-12)
    assert log.scans[1].pose[2] == pytest.approx(-math.pi + 0.05)
    assert "1 of 3 RAWLASER1 scans lie outside the ODOM poses' time span" in caplog.text


def test_rawlaser_without_odometry_is_an_error_naming_the_file(tmp_path):
    path = _write(tmp_path / "raw-only.log", [_rawlaser([1.0, 2.0, 3.0], -0.1, 0.1, 1.0)])
    with pytest.raises(CarmenLogError, match=r"raw-only.log: no valid front-laser scan"):
        read_carmen(path)


def test_a_log_with_the_same_scans_in_two_forms_is_read_once(tmp_path, caplog):
    ranges, pose = [1.0, 2.0, 3.0], (0.0, 0.0, 0.0)
    lines = [_odom(0.0, 0.0, 0.0, 0.0), _odom(1.0, 0.0, 0.0, 10.0)]
    for t in (1.0, 2.0):
        lines += [_rawlaser(ranges, -0.1, 0.1, t), _robotlaser(ranges, -0.1, 0.1, pose, pose, stamp=t)]
    with caplog.at_level(logging.INFO, logger="emos.nav.localization.carmen"):
        log = read_carmen(_write(tmp_path / "both.log", lines))
    assert log.laser == "ROBOTLASER1" and len(log.scans) == 2
    assert "read the 2 ROBOTLASER1 scans; 2 RAWLASER1 lines not used" in caplog.text


def test_flaser_takes_the_logs_field_of_view_and_laser_range(tmp_path):
    ranges = [1.0] * 101
    path = _write(tmp_path / "fov.log", ["PARAM laser_front_laser_fov 100 host 0\n", "PARAM robot_front_laser_max 8.1 host 0\n",
                                         _flaser(ranges, (0.0, 0.0, 0.0), 1.0)])
    log = read_carmen(path)
    scan = log.scans[0]
    assert scan.angles[0] == pytest.approx(math.radians(-50)) and scan.angles[-1] == pytest.approx(math.radians(50))
    assert scan.max_range == 8.1 and log.no_echo_range() == 8.1
    # radians as CARMEN printed them (csail's 3.14159) are 180 degrees, bit for bit the default
    path = _write(tmp_path / "rad.log", ["PARAM laser_front_laser_fov 3.14159 host 0\n", _flaser([1.0] * 361, (0.0, 0.0, 0.0), 1.0)])
    assert np.array_equal(read_carmen(path).scans[0].angles, beam_angles(361))
    # without the parameters: 180 degrees, no range of its own (30 m rules)
    plain = read_carmen(_write(tmp_path / "plain.log", [_flaser([1.0] * 180, (0.0, 0.0, 0.0), 1.0)]))
    assert np.array_equal(plain.scans[0].angles, beam_angles(180)) and plain.no_echo_range() == 30.0


def test_bad_laser_lines_and_parameters_are_skipped_and_named(tmp_path, caplog):
    good = _robotlaser([1.0, 2.0, 3.0], -0.1, 0.1, (0.0, 0.0, 0.0))
    lines = [good,
             good.replace(" 3 1.0 2.0 3.0 ", " 4 1.0 2.0 3.0 ", 1),  # 2: a count the line does not hold
             _robotlaser([1.0, 2.0, 3.0], 0.0, 4.0, (0.0, 0.0, 0.0)),        # 3: beams wider than a turn
             _robotlaser([1.0, 2.0, 3.0], 0.0, 0.1, (0.0, 0.0, 0.0), max_range=-1.0),  # 4: negative range
             " ".join(good.split()[:12]) + "\n",                              # 5: torn after the ranges
             "PARAM laser_front_laser_fov 400 host 0\n",                     # 6: no such field of view
             "PARAM robot_frontlaser_offset nan host 0\n"]                   # 7: not a number
    with caplog.at_level(logging.WARNING, logger="emos.nav.localization.carmen"):
        log = read_carmen(_write(tmp_path / "bad.log", lines), report=RateLimitedLog(interval=0.0))
    assert len(log.scans) == 1 and log.skipped == 6
    text = caplog.text
    assert "line 3: skipping a malformed ROBOTLASER1 line (3 beams 4.0 rad apart do not fit in one turn)" in text
    assert "line 4: skipping a malformed ROBOTLASER1 line (maximum range -1.0 is not positive)" in text
    assert "line 6: skipping a malformed PARAM line (field of view 400 is not in (0, 360] degrees)" in text
    assert "line 7: skipping a malformed PARAM line (a value is not finite)" in text


def _as_forms(src: Path, dst_robot: Path, dst_raw: Path, scans: int) -> None:
    """The first ``scans`` FLASER scans of a real log rewritten as ROBOTLASER1, and as RAWLASER1
    with an ODOM pose at each scan's timestamp (so interpolation returns it exactly)."""
    log = read_carmen(src)
    robot, raw = [], []
    for s in log.scans[:scans]:
        n = len(s.ranges)
        res = math.pi / n  # 180 beams over 180 degrees, as beam_angles(180)
        robot.append(_robotlaser(s.ranges.tolist(), -math.pi / 2, res, s.pose.tolist(), s.pose.tolist(), stamp=s.timestamp,
                                 max_range=81.83))
        raw += [_odom(*s.pose.tolist(), s.timestamp), _rawlaser(s.ranges.tolist(), -math.pi / 2, res, s.timestamp, 81.83)]
    _write(dst_robot, robot)
    _write(dst_raw, raw)


@pytest.mark.process
def test_the_benchmark_gives_the_same_answer_whichever_form_the_log_is_written_in(tmp_path):
    robot, raw = tmp_path / "aces-robotlaser.log.gz", tmp_path / "aces-rawlaser.log"
    _as_forms(ACES_LOG, robot, raw, 60)
    results = []
    for log in (ACES_LOG, robot, raw):
        out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "localize", "--log", str(log),
                              "--seeds", "1", "--max-scans", "60", "--json"],
                             capture_output=True, text=True, timeout=300, check=False)
        assert out.returncode == 0, out.stderr
        results.append(json.loads(out.stdout))
    assert [r["laser"] for r in results] == ["FLASER", "ROBOTLASER1", "RAWLASER1"]
    assert [r["no_echo_range_m"] for r in results] == [30.0, 30.0, 30.0]
    rows = [r["results"][0] for r in results]
    assert rows[0]["scans"] == 60 and rows[0]["converged_rate"] == 1.0
    for key in ("position_rmse_m", "heading_rmse_deg", "converged_rate"):
        assert rows[1][key] == rows[0][key], key  # the same numbers read from other words
        # RAWLASER1's headings pass through unwrapping and wrapping again: equal to a few ulps
        assert rows[2][key] == pytest.approx(rows[0][key], rel=1e-9), key
