"""The arc sampler as a path-following controller (ControllersID.ARC_SAMPLER), closed loop."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.nav.controllers import ControllersID, ControlStatus, make_controller
from tests.nav.sim2d import World, make_robot, run_closed_loop, straight_path

pytestmark = pytest.mark.unit


def test_arc_sampler_follows_a_path_around_an_obstacle_and_stops_at_the_goal():
    robot = make_robot("DIFFERENTIAL_DRIVE")
    ctrl = make_controller(ControllersID.ARC_SAMPLER, robot)
    ctrl.set_path(straight_path(4.0))
    world = World(circles=[(2.0, 0.05, 0.25)])
    result = run_closed_loop(ctrl, robot, world, (0.0, 0.0, 0.0), max_steps=400)
    assert result.reached, result.statuses[-5:]
    assert result.min_clearance > 0.0
    assert np.abs(result.poses[:, 1]).max() > 0.2  # it went round, not through


def test_arc_sampler_reports_blocked_when_boxed_in():
    robot = make_robot("DIFFERENTIAL_DRIVE")
    ctrl = make_controller("ArcSampler", robot)
    ctrl.set_path(straight_path(4.0))
    # Walls 2 cm from the footprint (a 0.3 m square) on all four sides: no arc gets anywhere.
    t = np.linspace(-0.3, 0.3, 61)
    walls = np.r_[np.c_[np.full(61, 0.17), t], np.c_[np.full(61, -0.17), t], np.c_[t, np.full(61, 0.17)], np.c_[t, np.full(61, -0.17)]]
    res = ctrl.compute(np.zeros(3), np.zeros(3), walls)
    assert res.status is ControlStatus.BLOCKED and not res.command.any()
