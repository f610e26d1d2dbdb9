"""The CARMEN log reader (every line validated, bad ones skipped with a counted, rate-limited
log naming the file and line) and the seeded odometry noise model."""
from __future__ import annotations

import gzip
import logging
import math

import numpy as np
import pytest

from emos.actors.nav.localization import CarmenLogError, beam_angles, noisy_odometry, read_carmen, relative_pose
from tests.localization.helpers import ACES_LOG

pytestmark = pytest.mark.unit


def _flaser(ranges, pose=(1.0, 2.0, 0.5), stamp=12.5) -> str:
    n = len(ranges)
    return f"FLASER {n} {' '.join(map(str, ranges))} {pose[0]} {pose[1]} {pose[2]} {pose[0]} {pose[1]} {pose[2]} {stamp} host {stamp}\n"


def test_reads_the_shipped_radish_log():
    log = read_carmen(ACES_LOG)
    assert len(log.scans) == 440 and log.skipped == 0
    assert all(len(s.ranges) == 180 for s in log.scans)
    assert log.odometry.shape == (7814, 4)
    assert log.name == "aces-corrected"
    first = log.scans[0]
    assert first.ranges[:2].tolist() == [6.66, 6.86]
    assert np.allclose(first.pose, [0.89706, -0.180771, -0.454003]) and first.timestamp == pytest.approx(21.0199)


def test_beam_angles_follow_the_carmen_conventions():
    a180 = beam_angles(180)  # 1 degree apart from -90, the last at 89
    assert a180[0] == pytest.approx(-math.pi / 2) and a180[-1] == pytest.approx(math.radians(89))
    for n in (181, 361):  # both ends included
        a = beam_angles(n)
        assert a[0] == pytest.approx(-math.pi / 2) and a[-1] == pytest.approx(math.pi / 2)


def test_malformed_lines_are_skipped_counted_and_logged_with_file_and_line(tmp_path, caplog):
    good = _flaser([1.0, 2.0, 3.0])
    lines = ["# comment\n", "PARAM x 1\n", good,
             "FLASER 3 1.0 2.0\n",                          # line 4: too short
             _flaser([1.0, float("nan"), 3.0]),             # line 5: NaN range
             _flaser([1.0, -2.0, 3.0]),                     # line 6: negative range
             "FLASER three 1 2 3 4 5 6 7 8 9 10 h 1\n",      # line 7: count is not a number
             "ODOM 1 2 0.1 0 0 0 5.0 host 5.0\n", "ODOM 1 two\n", good]
    lines += ["FLASER 2 x\n"] * 50  # a burst of the same problem: counted, not 50 lines
    path = tmp_path / "bad.log.gz"
    with gzip.open(path, "wt") as fh:
        fh.writelines(lines)
    with caplog.at_level(logging.WARNING, logger="emos.nav.localization.carmen"):
        log = read_carmen(path)
    assert len(log.scans) == 2 and [s.line for s in log.scans] == [3, 10]
    assert log.odometry.tolist() == [[5.0, 1.0, 2.0, 0.1]]
    assert log.skipped == 55
    text = caplog.text
    assert f"CARMEN log {path} line 4: skipping a malformed FLASER line" in text
    assert "55 malformed lines skipped in all" in text
    assert len(caplog.records) < 10, "the burst of bad lines is rate-limited"


def test_a_log_without_scans_is_an_error_naming_the_file(tmp_path):
    path = tmp_path / "empty.log"
    path.write_text("# nothing\nODOM 0 0 0 0 0 0 0 h 0\n")
    with pytest.raises(CarmenLogError, match=r"empty.log: no valid front-laser scan"):
        read_carmen(path)
    with pytest.raises(CarmenLogError, match="cannot read it"):
        read_carmen(tmp_path / "missing.log")


def test_noisy_odometry_is_seeded_and_follows_the_alphas():
    n = 2000
    ref = np.column_stack([np.arange(n) * 1.0, np.zeros(n), np.zeros(n)])  # 1 m steps, straight
    a = noisy_odometry(ref, (0.01, 0.001, 0.01, 0.001), seed=3)
    assert np.array_equal(a, noisy_odometry(ref, (0.01, 0.001, 0.01, 0.001), seed=3)), "same seed, same odometry"
    assert not np.array_equal(a, noisy_odometry(ref, (0.01, 0.001, 0.01, 0.001), seed=4))
    assert np.allclose(noisy_odometry(ref, (0.0, 0.0, 0.0, 0.0), seed=3), ref), "no noise: the reference itself"
    steps = relative_pose(a[:-1], a[1:])
    trans = np.hypot(steps[:, 0], steps[:, 1])
    # sd(trans) = sqrt(alpha3) * 1 m = 0.1 m; sd(heading change) = sqrt(2 * alpha2) * 1 m (rot1 and rot2)
    assert np.std(trans) == pytest.approx(0.1, rel=0.1)
    assert np.std(steps[:, 2]) == pytest.approx(math.sqrt(2 * 0.001), rel=0.15)
    assert np.mean(trans) == pytest.approx(1.0, abs=0.01), "zero-mean noise"
