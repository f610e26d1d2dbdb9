"""The MotionServer's tests last their ``test_period`` of robot time, not of wall time.

Under a simulator (``use_sim_time``, ``emos run --lockstep``) a test of 10 s must command the
robot for 10 simulated seconds, however fast or slow the simulation runs against the wall clock;
before, it timed itself with the wall clock, so a simulation running at a fraction of real time
recorded a fraction of the motion. The real node runs in ``emos.testing.ComponentHarness``: its
clock moves 10 simulated seconds in well under a wall second, and a kinematic base answers every
tick's command with odometry.
"""
from __future__ import annotations

import csv

import numpy as np
import pytest

from emos import msgs as M
from emos.testing import ComponentHarness
from tests.nav.components.fake_base import CommandFollower, base_messages

pytestmark = pytest.mark.unit


def test_each_circle_test_commands_the_robot_for_its_period_of_robot_time(tmp_path):
    from emos.actors.nav.components import MotionServer, MotionServerConfig

    server = MotionServer(component_name="motion_server", config=MotionServerConfig(
        test_period=2.0, circle_test_velocity=0.2, circle_test_omega=0.4, tests_folder=str(tmp_path)))
    base = CommandFollower((0.0, 0.0, 0.0), command="/control")

    def answer(h: ComponentHarness) -> None:
        v, w = base.move(h)
        odom, _ = base_messages(base.pose, v, w, fov=np.pi)
        h.feed("/odom", odom)

    with ComponentHarness(server) as h:
        answer(h)
        h.feed("/run_tests", M.Bool(data=True))
        h.advance(3 * 2.0 + 1.0, each_tick=answer)  # three tests of 2 s each, and a second to finish
        commands = h.outputs("/control")
    files = {name: sorted(tmp_path.glob(f"motion_server_{name}_*.csv")) for name in ("circle_forward", "circle_inverse", "circle_backward")}
    assert all(len(found) == 1 for found in files.values()), sorted(p.name for p in tmp_path.iterdir())
    for name, (found,) in files.items():
        with open(found, newline="") as f:
            t = [float(row["t"]) for row in csv.DictReader(f)]
        # one row per 0.1 s tick over the 2 s of robot time the test lasts
        assert 19 <= len(t) <= 21 and t[-1] < 2.0 and t[-1] > 1.8, (name, len(t), t[:3], t[-3:])
    moving = [c for c in commands if abs(c.linear.x) > 0]
    assert 57 <= len(moving) <= 63, len(moving)  # 3 x 2 s at 10 Hz, then a stop
    assert commands[-1].linear.x == 0.0 and commands[-1].angular.z == 0.0
