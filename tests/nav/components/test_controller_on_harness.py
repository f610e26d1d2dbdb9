"""The Controller on a point cloud, on the component harness (no process tree): the floor is no
obstacle, a wall ahead stops the robot. Its process wiring is tested with the whole stack in
test_nav_stack_processes.py and test_nav_run_types_and_safety.py."""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit


def test_controller_on_a_point_cloud_ignores_the_floor_and_stops_for_a_wall():
    from emos.actors.nav.components import Controller, ControllerConfig
    from emos.actors.nav.components.convert import path_msg

    controller = Controller(component_name="controller", config=ControllerConfig(algorithm="DWA", use_direct_sensor=True))
    controller.inputs(sensor_data=Topic(name="/cloud", msg_type="PointCloud2"))
    gx, gy = np.meshgrid(np.linspace(-1, 3, 41), np.linspace(-1, 1, 21))
    floor = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    wall = np.c_[np.full(21, 0.35), np.linspace(-1, 1, 21), np.full(21, 0.15)]

    def sensing(points):
        def feed(h: ComponentHarness) -> None:  # the robot stands at the origin, facing the path
            odom = M.Odometry()
            odom.pose.pose.orientation.w = 1.0
            h.feed("/odom", odom)
            h.feed("/cloud", M.PointCloud2.from_xyz(points))
        return feed

    with ComponentHarness(controller) as h:
        h.feed("/plan", path_msg(np.c_[np.linspace(0, 3, 61), np.zeros(61), np.zeros(61)], "map"))
        h.advance(2.0, each_tick=sensing(floor))
        moving = h.outputs("/control")
        assert max(c.linear.x for c in moving) > 0.1  # the floor is not an obstacle
        h.advance(2.0, each_tick=sensing(np.r_[floor, wall]))
        blocked = h.outputs("/control")
        assert blocked and max(c.linear.x for c in blocked[-5:]) < 0.05  # a wall 0.25 m ahead is
