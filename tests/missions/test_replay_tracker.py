"""scripts/replay_tracker.py on real simulator scans: the house with its person, the patrol's
robot standing in the right room watching the corridor (pybullet's lidar, the recorder's file
format), replayed as the stack runs the tracker."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]


def _record(path: Path, seconds: float = 30.0) -> None:
    """What scripts/record_tracker_inputs.py saves, from a robot standing at (6.0, 2.2)."""
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.sim.component.config import SimulatorConfig
    from emos.actors.sim.component.worlds import build_setup
    from emos.actors.sim.sensors.lidar import ScanReading

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.2, 0.3]))
    setup = build_setup(SimulatorConfig(world="house_person", robot=robot, spawn=(6.0, 2.2, math.pi / 2)), True, False)
    rows: list[tuple] = []
    for _, reading in setup.world.run_for(seconds):
        if isinstance(reading, ScanReading):
            pts = reading.points()
            rows.append((reading.stamp, pts, np.array(setup.robot.pose, dtype=float), reading.angle_increment))
    np.savez_compressed(path, stamp=np.array([r[0] for r in rows]), pose=np.array([r[2] for r in rows]),
                        angle_increment=np.array([r[3] for r in rows]), pose_stamp=np.full(len(rows), np.nan),
                        twist=np.zeros((len(rows), 3)), counts=np.array([len(r[1]) for r in rows]),
                        points=np.concatenate([r[1] for r in rows]))


def test_the_replay_tracks_the_house_person_on_full_simulator_scans(tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import replay_tracker
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    rec = tmp_path / "rec.npz"
    _record(rec)
    scans = replay_tracker.load(str(rec))
    assert len(scans) >= 250 and all(len(s["points"]) > 300 for s in scans)  # 10 Hz; a full scan, not half
    stack = replay_tracker.score(replay_tracker.replay(scans, "subtract"))
    assert stack["sightings"] >= 1 and stack["never"] == 0 and stack["tracked"] > 0.8, stack
    assert stack["false_scans"] <= 0.05, stack
