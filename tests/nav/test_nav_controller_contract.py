"""The contract between the Controller component and its algorithms (PathFollower): every path
controller declares its capabilities as attributes, which the component reads without probing."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.controllers import ControllersID
from emos.actors.nav.controllers.arc_sampler import ArcSamplerConfig
from emos.actors.nav.controllers.follower import PathFollower
from emos.actors.nav.controllers.registry import CONTROLLERS, make_controller
from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType

pytestmark = pytest.mark.unit

VISION = {ControllersID.VISION_IMG, ControllersID.VISION_DEPTH}


def _robot() -> RobotConfig:
    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))


@pytest.mark.parametrize("cid", [c for c in CONTROLLERS if c not in VISION], ids=lambda c: c.value)
def test_every_path_controller_is_a_path_follower_with_its_capabilities_declared(cid):
    follower = make_controller(cid, _robot())
    assert isinstance(follower, PathFollower)
    assert len(tuple(follower.scan_pose)) == 3
    assert isinstance(follower.tracks_movers, bool) and isinstance(follower.waiting, bool)
    assert follower.progress is None  # no path yet
    follower.set_path(np.array([[0.0, 0.0], [2.0, 0.0]]))
    result = follower.compute(np.zeros(3), np.zeros(3), None)
    assert result.commands.shape[1] == 3 and follower.progress is not None


def test_a_capability_is_declared_by_the_algorithm_that_has_it():
    plain = make_controller(ControllersID.ARC_SAMPLER, _robot())
    movers = make_controller(ControllersID.ARC_SAMPLER, _robot(), ArcSamplerConfig(movers={}))
    assert plain.tracks_movers is False and movers.tracks_movers is True


def test_a_follower_without_compute_says_so():
    class Half(PathFollower):
        pass

    with pytest.raises(NotImplementedError, match="Half does not implement compute"):
        Half(_robot(), CONTROLLERS[ControllersID.PURE_PURSUIT][1]()).compute(np.zeros(3), np.zeros(3))
