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
