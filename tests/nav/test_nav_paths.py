"""Path CSV files and the driven-path recorder."""
import math

import numpy as np
import pytest

from emos.actors.nav.paths import PathFileError, PathRecorder, load_path_csv, save_path_csv

pytestmark = pytest.mark.unit


def test_csv_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    path = np.column_stack((rng.normal(size=50) * 10, rng.normal(size=50), rng.uniform(-math.pi, math.pi, 50)))
    f = save_path_csv(path, tmp_path / "sub" / "p.csv")
    assert f.read_text().splitlines()[0] == "x,y,yaw"
    assert np.array_equal(load_path_csv(f), path)


def test_xy_only_files_get_headings_along_the_path(tmp_path):
    (tmp_path / "xy.csv").write_text("x,y\n0,0\n1,0\n1,1\n")
    p = load_path_csv(tmp_path / "xy.csv")
    assert p.shape == (3, 3)
    np.testing.assert_allclose(p[:, 2], [0.0, math.pi / 2, math.pi / 2])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty file"),
        ("a,b,c\n1,2,3\n", "header must be"),
        ("x,y,yaw\n1,2,3\n1,2\n", ":3: expected 3 values"),
        ("x,y,yaw\n1,2,3\n1,two,3\n", ":3: non-numeric"),
        ("x,y,yaw\n1,nan,3\n", ":2: NaN or inf"),
    ],
)
def test_bad_csv_files_name_the_line(tmp_path, text, message):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(PathFileError, match=message):
        load_path_csv(f)


def test_missing_file_and_bad_arrays(tmp_path):
    with pytest.raises(PathFileError, match="cannot read"):
        load_path_csv(tmp_path / "none.csv")
    with pytest.raises(ValueError, match="NaN"):
        save_path_csv(np.array([[0, 0, np.nan]]), tmp_path / "x.csv")
    with pytest.raises(ValueError, match="shape"):
        save_path_csv(np.zeros((3, 4)), tmp_path / "x.csv")


def test_recorder_keeps_poses_by_distance_and_angle(tmp_path):
    rec = PathRecorder(min_distance=0.5, min_angle=0.25)
    xs = np.linspace(0, 2.0, 41)  # 5 cm steps
    poses = np.column_stack((xs, np.zeros_like(xs), np.zeros_like(xs)))
    kept = rec.add_many(poses)
    assert kept == 5  # 0, 0.5, 1.0, 1.5, 2.0
    np.testing.assert_allclose(rec.path()[:, 0], [0, 0.5, 1.0, 1.5, 2.0])
    # Turning in place in 0.1 rad steps: a pose every 0.3 rad (first step >= 0.25).
    for yaw in np.linspace(0.0, 1.0, 11):
        rec.add(2.0, 0.0, yaw)
    assert rec.path()[-1, 2] == pytest.approx(1.0)
    assert len(rec) == 8  # 0.3, 0.6, 0.9 kept; 1.0 closes the path as the latest pose
    assert len(rec.path()) == 9 and len(rec.path(include_latest=False)) == 8
    back = load_path_csv(rec.save(tmp_path / "driven.csv"))
    assert np.array_equal(back, rec.path())
    with pytest.raises(ValueError, match="finite"):
        rec.add(0.0, math.inf, 0.0)
    with pytest.raises(ValueError, match="min_distance"):
        PathRecorder(min_distance=-1)
    rec.clear()
    assert rec.path().shape == (0, 3)


def test_recorder_handles_angle_wrap():
    rec = PathRecorder(min_distance=1.0, min_angle=0.5)
    rec.add(0, 0, math.pi - 0.1)
    assert not rec.add(0, 0, -math.pi + 0.1)  # only 0.2 rad apart across the wrap
    assert rec.add(0, 0, -math.pi + 0.45)


def test_recorder_time_step_throttles_and_skips_standing_still():
    # Binary-exact times (1/32 s odometry, 1/8 s recording step) keep the count unambiguous.
    rec = PathRecorder(min_distance=0.01, min_angle=0.01, recording_time_step=0.125)
    t = np.arange(32) / 32.0  # 0.5 m/s for 1 s ...
    poses = np.column_stack((0.5 * t, np.zeros_like(t), np.zeros_like(t)))
    assert rec.add_many(poses, stamps=t) == 8  # one pose per 0.125 s
    np.testing.assert_allclose(np.diff(rec.path(include_latest=False)[:, 0]), 0.0625)
    # ... then standing still for a second: the stop position is kept once, then nothing
    # more although time passes.
    still = np.tile(poses[-1], (32, 1))
    assert rec.add_many(still, stamps=1.0 + t) == 1
    assert np.allclose(rec.path(include_latest=False)[-1], poses[-1])
    with pytest.raises(ValueError, match="stamp"):
        rec.add(1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="stamps"):
        rec.add_many(poses, stamps=t[:3])
    with pytest.raises(ValueError, match="recording_time_step"):
        PathRecorder(recording_time_step=0)
