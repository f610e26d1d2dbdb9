"""The Controller's ``speed_mask``: inside a speed zone its commands are capped to the zone's
limit (Nav2's speed filter, percent of the robot's maximum); outside it they are not."""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M
from emos.actors.nav.costmap import Zone
from emos.actors.nav.costmap.mask_io import write_mask
from emos.testing import ComponentHarness

from .helpers import room_grid

pytestmark = pytest.mark.unit


def _top_speed(odom_x: float, mask: str) -> float:
    from emos.actors.nav.components import Controller, ControllerConfig
    from emos.actors.nav.components.convert import path_msg

    controller = Controller(component_name="controller", config=ControllerConfig(algorithm="DWA", speed_mask=mask))
    controller.inputs(sensor_data=Topic(name="/cloud", msg_type="PointCloud2"))
    far = np.c_[np.full(5, 9.0), np.linspace(-1, 1, 5), np.full(5, 0.15)]

    def feed(h: ComponentHarness) -> None:
        odom = M.Odometry()
        odom.pose.pose.position.x, odom.pose.pose.position.y = odom_x, 1.0
        odom.pose.pose.orientation.w = 1.0
        h.feed("/odom", odom)
        h.feed("/cloud", M.PointCloud2.from_xyz(far - [odom_x, 1.0, 0.0]))

    with ComponentHarness(controller) as h:
        h.feed("/plan", path_msg(np.c_[np.linspace(odom_x, odom_x + 3, 61), np.ones(61), np.zeros(61)], "map"))
        h.advance(3.0, each_tick=feed)
        return max(c.linear.x for c in h.outputs("/control"))


def test_commands_are_capped_inside_a_speed_zone(tmp_path):
    zone = Zone(name="hall", kind="speed", polygon=((0.0, 0.0), (2.0, 0.0), (2.0, 4.0), (0.0, 4.0)), value=5.0)
    mask = str(write_mask(tmp_path / "speed.yaml", [zone], "speed_percent", room_grid()))
    cap = 0.05 * 1.0  # 5 % of the default robot's max_vel (1 m/s)
    assert _top_speed(1.0, mask) <= cap + 1e-9
    assert _top_speed(3.0, mask) > cap + 0.05  # outside the zone: the usual speed
