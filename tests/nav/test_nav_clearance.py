"""Footprint clearance of many poses: the k-d tree path (used for large pose x obstacle counts)
gives the same exact distances as the all-pairs path, for every planar footprint."""
import numpy as np
import pytest

from emos.actors.nav.controllers import clearance as C
from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType

pytest.importorskip("scipy")

pytestmark = [pytest.mark.sim, pytest.mark.process]

FOOTPRINTS = {
    "box": (RobotGeometry.Type.BOX, np.array([0.5, 0.3, 0.2])),
    "cylinder": (RobotGeometry.Type.CYLINDER, np.array([0.2, 0.3])),
    "ellipse": (RobotGeometry.Type.ELLIPSOID, np.array([0.3, 0.15, 0.2])),  # semi-axes
}


@pytest.mark.parametrize("shape", sorted(FOOTPRINTS))
@pytest.mark.parametrize("crowd", [False, True])
def test_kdtree_and_all_pairs_agree(shape, crowd, monkeypatch):
    kind, params = FOOTPRINTS[shape]
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=kind, geometry_params=params)
    rng = np.random.default_rng(7)
    poses = np.c_[rng.uniform(-2, 2, (40, 25, 2)).reshape(-1, 2), rng.uniform(-np.pi, np.pi, 1000)].reshape(40, 25, 3)
    # crowd: a dense wall, so many poses have more than the k nearest inside their bound
    obstacles = (np.c_[np.linspace(-2, 2, 800), rng.normal(0, 0.02, 800)] if crowd else rng.uniform(-2.5, 2.5, (300, 2)))
    monkeypatch.setattr(C, "KDTREE_PAIRS", 10**12)  # all pairs
    want = C.pose_clearance(robot, poses, obstacles)
    monkeypatch.setattr(C, "KDTREE_PAIRS", 0)  # k-d tree
    got = C.pose_clearance(robot, poses, obstacles)
    assert got.shape == (40, 25)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)  # all pairs compares centres in float32
    assert (got < 0).any() and (got > 0).any()


def test_scipy_k_d_tree_is_imported_when_a_controller_is_built_not_with_the_package():
    """Start-up: importing scipy.spatial takes a good fraction of a second, and every process of
    a run imports the nav package; only a process that builds a controller needs the tree."""
    import subprocess
    import sys

    code = """
import sys
import emos.actors.nav, emos.tools.barn.stack
assert "scipy.spatial" not in sys.modules, "imported with the package"
from emos.actors.nav.controllers import Stanley
from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType
import numpy as np
Stanley(RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.2, 0.3])))
assert "scipy.spatial" in sys.modules, "not warmed up by the controller"
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]


@pytest.mark.parametrize("shape", sorted(FOOTPRINTS))
@pytest.mark.parametrize("crowd", [False, True])
def test_trajectory_minimum_refines_only_where_it_can_win_and_equals_the_full_minimum(shape, crowd, monkeypatch):
    """The controllers' per-trajectory clearance skips the exact footprint distance at poses whose
    bounding-circle bound cannot be the minimum: the values must be those of every pose refined."""
    kind, params = FOOTPRINTS[shape]
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=kind, geometry_params=params)
    rng = np.random.default_rng(11)
    # rollouts: 60 arcs of 30 poses from near the origin, so closest approaches differ per arc
    t = np.linspace(0.0, 1.5, 30)
    v, w = rng.uniform(0.2, 1.0, 60), rng.uniform(-2.0, 2.0, 60)
    yaw = w[:, None] * t
    x = np.cumsum(v[:, None] * np.cos(yaw) * 0.05, axis=1) - 1.0
    y = np.cumsum(v[:, None] * np.sin(yaw) * 0.05, axis=1)
    poses = np.stack([x, y, yaw], axis=-1)
    # crowd: a dense wall beside the arcs; else a few posts, as a scan of a sparse room shows them
    obstacles = (np.c_[np.linspace(-2, 2, 800), rng.normal(0.4, 0.02, 800)] if crowd
                 else np.concatenate([c + 0.1 * np.c_[np.cos(a), np.sin(a)] for c in rng.uniform(-2.0, 2.0, (6, 2)) for a in [np.linspace(0, 6.2, 20)]]))
    valid = rng.random((60, 30)) > 0.2
    valid[0] = False  # a trajectory with nothing to judge: inf, as before
    monkeypatch.setattr(C, "KDTREE_PAIRS", 0)  # the k-d tree path, where the pruning applies
    refined = []
    original = C._clearance_kdtree
    monkeypatch.setattr(C, "_clearance_kdtree", lambda r, flat, o, tree: refined.append(len(flat)) or original(r, flat, o, tree))
    want = np.where(valid, C.pose_clearance(robot, poses, obstacles), np.inf).min(axis=-1)
    refined.clear()
    got = C.trajectory_min_clearance(robot, poses, obstacles, valid)
    np.testing.assert_array_equal(got, want)
    assert np.isinf(got[0]) and np.isfinite(got[1:]).all()
    if kind is not RobotGeometry.Type.CYLINDER:
        assert 0 < sum(refined) < 0.8 * valid.sum(), f"refined {sum(refined)} of {valid.sum()} poses"
