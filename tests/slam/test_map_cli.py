"""`emos map build RUN.mcap -o office` and `emos map show office.yaml`, as a user runs them (real
processes): a recording of a drive around a room with drifting odometry becomes a map_server
map that the MapServer's loader reads, and a picture of it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gtsam")
pytest.importorskip("mcap")

from emos.actors.nav.localization import noisy_odometry
from emos.actors.nav.maps import load_map
from emos.interop.mcap_bag import BagWriter
from emos.msgs import LaserScan, Odometry
from emos.msgs.geometry import Point, Pose, Quaternion
from emos.msgs.std import Header
from tests.localization.helpers import BEAMS, MAX_RANGE, cast, loop_path, room_map

pytestmark = pytest.mark.process


def _record(path) -> None:
    grid, truth = room_map(), loop_path(60)
    odom = noisy_odometry(truth, (0.01, 0.001, 0.01, 0.001), seed=3)
    inc = float(BEAMS[1] - BEAMS[0])
    with BagWriter(path) as bag:
        for i, (t, o) in enumerate(zip(truth, odom)):
            ns = 1_000_000_000 + i * 100_000_000
            msg = Odometry(header=Header(frame_id="odom"), child_frame_id="base_link")
            msg.pose.pose = Pose(position=Point(x=float(o[0]), y=float(o[1])), orientation=Quaternion.from_yaw(float(o[2])))
            bag.write("/odom", msg, ns)
            scan = LaserScan(angle_min=float(BEAMS[0]), angle_max=float(BEAMS[-1]), angle_increment=inc, range_min=0.05,
                             range_max=MAX_RANGE, ranges=cast(grid, t).astype(np.float32))
            bag.write("/scan", scan, ns + 50_000_000)


def test_map_build_then_show(tmp_path):
    run = tmp_path / "run.mcap"
    _record(run)
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "build", str(run), "-o", str(tmp_path / "office")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "nodes" in out.stderr and "office.yaml" in out.stdout
    grid = load_map(tmp_path / "office.yaml")
    assert (tmp_path / "office.pgm").exists()
    assert (grid.data == 100).sum() > 200 and (grid.data == 0).sum() > 1000
    # The pose graph beside it, loadable by a Mapper in localization mode.
    from emos.actors.nav.mapping.slam import load_posegraph

    graph = load_posegraph(tmp_path / "office.posegraph.npz")
    assert len(graph.poses) >= 2 and len(graph.poses) == len(graph.ranges) == len(graph.angles)
    shown = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "show", str(tmp_path / "office.yaml")],
                           capture_output=True, text=True, timeout=120)
    assert shown.returncode == 0, shown.stderr
    assert (tmp_path / "office.png").stat().st_size > 1000


def test_map_build_names_a_file_that_is_not_mcap(tmp_path):
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"hello, not a recording")
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "build", str(bad), "-o", str(tmp_path / "x")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "not.mcap" in out.stderr


OREBRO = Path(__file__).parent / "data" / "orebro-corrected.log.gz"


def test_map_build_reads_a_carmen_log_into_the_map_its_reference_makes(tmp_path):
    """A real Radish log (Örebro) built with `emos map build` gives the building's map: its walls
    lie where the map from the log's reference trajectory has them."""
    from emos.actors.nav.localization import build_reference_map, read_carmen

    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "build", str(OREBRO), "-o", str(tmp_path / "orebro")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "237 scans read" in out.stderr and "orebro.yaml" in out.stdout
    built = load_map(tmp_path / "orebro.yaml")
    log = read_carmen(OREBRO)
    ref = build_reference_map(log.poses, [s.ranges for s in log.scans], [s.angles for s in log.scans],
                              resolution=built.resolution, max_range=30.0)
    walls = np.argwhere(built.data == 100)
    assert len(walls) > 1000
    # How far each wall cell of the built map lies from the nearest wall of the reference map
    # (occupied by map_server's threshold). The SLAM's trajectory is 5-10 cm from the log's
    # reference on these logs (docs/mapping.md), so its walls are too.
    from scipy.ndimage import distance_transform_edt

    to_wall = distance_transform_edt(ref.data < 65) * ref.resolution
    xy = built.map_to_world((walls[:, ::-1] + 0.5) * built.resolution)
    c, r = np.floor(ref.world_to_map(xy) / ref.resolution).astype(int).T
    inside = (r >= 0) & (r < ref.data.shape[0]) & (c >= 0) & (c < ref.data.shape[1])
    assert inside.all()
    d = to_wall[r, c]
    assert np.median(d) <= 0.1 and np.percentile(d, 90) <= 0.25, np.percentile(d, [50, 90])


def test_map_build_names_a_carmen_log_without_scans(tmp_path):
    bad = tmp_path / "empty.log"
    bad.write_text("PARAM robot_front_laser_max 50 host 0\nODOM 0 0 0 0 0 0 1.0 host 1.0\n")
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "build", str(bad), "-o", str(tmp_path / "x")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "empty.log: no valid front-laser scan" in out.stderr and "Traceback" not in out.stderr
