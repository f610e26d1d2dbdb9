"""A Localizer restarted within a run (killed or hung, then started again by the supervisor)
resumes from its last map -> odom composed with the odometry of then, not from the configured
initial pose: the main job's chaos scenario kills any component mid-mission."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from emos.actors.nav.components.convert import grid_msg
from emos.actors.nav.localization import noisy_odometry
from emos.core import lifecycle as L
from emos.testing import ComponentHarness
from tests.localization.helpers import cast, loop_path, room_map
from tests.localization.test_localizer_component import NOISE, _drive, _localizer, _odom, _scan

pytestmark = pytest.mark.unit


def _restart(h: ComponentHarness) -> None:
    """What a restart does to the component: configured and activated again, state lost (the
    run directory, where the estimate was kept, stays)."""
    h.deactivate()
    h._transition(L.Transition.CLEANUP)
    h._transition(L.Transition.CONFIGURE)
    h.activate()


@pytest.mark.parametrize("resume", [True, False])
def test_a_restarted_localizer_resumes_from_its_last_map_to_odom(resume):
    grid, path = room_map(), loop_path()
    odom = noisy_odometry(path, NOISE, seed=4)
    comp = _localizer(set_initial_pose=True, initial_pose=tuple(path[0]), resume_on_restart=resume)
    with ComponentHarness(comp) as h:
        map_msg = grid_msg(grid.data, grid.resolution, grid.origin, "map")
        h.feed("/map", map_msg)
        errors, _ = _drive(h, grid, path[:40], odom[:40])
        assert errors[-5:].max() < 0.1
        state = h.node.ctx.run_dir / "localizer.localizer.json"
        assert state.exists() == resume
        if resume:
            saved = json.loads(state.read_text())
            assert len(saved["correction"]) == 3 and np.asarray(saved["covariance"]).shape == (3, 3)
        _restart(h)
        # The robot is 40 poses (a third of the loop) away from the configured initial pose.
        h.feed("/map", map_msg)
        h.feed("/odom", _odom(odom[40]))
        h.feed("/scan", _scan(cast(grid, path[40])))
        h.advance(0.1)
        est = h.latest("/amcl_pose").pose.pose.position
        error = math.hypot(est.x - path[40, 0], est.y - path[40, 1])
        if resume:
            assert error < 0.1, error
            errors, _ = _drive(h, grid, path[41:60], odom[41:60])
            assert errors.max() < 0.1
        else:  # back at the configured start: the old behaviour, which lost the robot in the main job
            assert error > 1.0, error
