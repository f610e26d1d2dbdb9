"""Keepout zones kept by what drives the robot, not only by the Planner: the Controller takes the
zones' edges as obstacles, and the DriveManager's swept check stops any input's command that
would carry the footprint into a zone (Nav2 puts its keepout filter on the local costmap too).

The real Controller and DriveManager nodes run in ``ComponentHarness`` on robot time, closed
round the kinematic base of the room (tests/nav/components/fake_base.py: a 6 x 4 m room with a
wall from the bottom at x 2.8..3.2 up to y 2.6). The zone closes the corridor above that wall's
far side: x 2.0..2.6, y 2.8..4.0 (0.2 m between it and the wall, less than the robot's 0.3 m).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import msgs as M
from emos.actors.nav.costmap import KeepoutObstacles, Zone, load_filter_mask
from emos.actors.nav.costmap.mask_io import write_mask
from emos.testing import ComponentHarness
from tests.nav.components.test_drive_manager_on_robot_time import RoomBase, _driver, _robot

from .helpers import room_grid

pytestmark = pytest.mark.unit

ZONE = Zone(name="wet_floor", kind="keepout", polygon=((2.0, 2.8), (2.6, 2.8), (2.6, 4.0), (2.0, 4.0)))
RADIUS = 0.15  # the test robot's


@pytest.fixture
def mask(tmp_path) -> str:
    return str(write_mask(tmp_path / "keepout.yaml", [ZONE], "keepout", room_grid()))


def _overlap(pose) -> float:
    """How far (m) a footprint at ``pose`` reaches into the zone (<= 0: not at all)."""
    x, y = float(pose[0]), float(pose[1])
    dx = max(2.0 - x, 0.0, x - 2.6)
    dy = max(2.8 - y, 0.0, y - 4.0)
    return RADIUS - math.hypot(dx, dy) if (dx or dy) else RADIUS + min(x - 2.0, 2.6 - x, y - 2.8, 4.0 - y)


def test_the_edges_outline_the_zone_and_come_in_the_robots_frame(mask):
    keepout = KeepoutObstacles(load_filter_mask(mask, "keepout"))
    pts = keepout.points
    on_side = np.isclose(pts[:, 0], 2.0) | np.isclose(pts[:, 0], 2.6)
    on_end = np.isclose(pts[:, 1], 2.8) | np.isclose(pts[:, 1], 4.0)
    assert np.all((on_side & (pts[:, 1] >= 2.8 - 1e-9) & (pts[:, 1] <= 4.0 + 1e-9)) | (on_end & (pts[:, 0] >= 2.0 - 1e-9) & (pts[:, 0] <= 2.6 + 1e-9)))
    west = np.sort(pts[np.isclose(pts[:, 0], 2.0), 1])
    assert west[0] == pytest.approx(2.8) and west[-1] == pytest.approx(4.0) and np.diff(west).max() <= 0.025 + 1e-9

    # Facing north from (1.7, 3.3): the zone's west side is 0.3 m to the robot's right (-y).
    near, inside = keepout.around(np.array([1.7, 3.3, math.pi / 2]), reach=0.5)
    assert inside is None and len(near)
    assert np.allclose(near[:, 1].max(), -0.3) and np.all(np.hypot(*near.T) <= 0.5 + 1e-9)
    # `clear` leaves out what the footprint already touches; inside the zone: nothing, and its name.
    assert len(keepout.around(np.array([1.9, 3.3, 0.0]), reach=0.5, clear=0.15)[0]) < len(keepout.around(np.array([1.9, 3.3, 0.0]), reach=0.5)[0])
    none, inside = keepout.around(np.array([2.3, 3.3, 0.0]), reach=2.0)
    assert len(none) == 0 and inside == "'wet_floor' (keepout.yaml)"
    assert keepout.zone_by(np.array([2.0, 3.3])) == "'wet_floor' (keepout.yaml)"


def _controller(mask: str):
    from emos.actors.nav.components import Controller, ControllerConfig
    from emos.actors.nav.controllers import ControllersID

    return Controller(component_name="controller", config=ControllerConfig(
        robot=_robot(), algorithm=ControllersID.PURE_PURSUIT.value, keepout_mask=mask, loop_rate=10.0))


@pytest.mark.parametrize("with_mask", [True, False])
def test_the_controller_does_not_follow_a_plan_into_a_keepout_zone(mask, with_mask):
    """A plan straight through the zone (made without the mask): with it, the Controller never
    takes the footprint into the zone (nor past it: there is no way round); without it, it drives through."""
    from emos.actors.nav.components.convert import path_msg

    base = RoomBase(start=(1.0, 3.3, 0.0))
    base.command = "/control"
    poses = []

    def tick(h: ComponentHarness) -> None:
        base(h)
        poses.append(base.pose.copy())

    with ComponentHarness(_controller(mask if with_mask else ""), start_time=10.0) as h:
        h.feed("/plan", path_msg(np.c_[np.linspace(1.0, 5.0, 81), np.full(81, 3.3), np.zeros(81)], "map"))
        h.advance(25.0, each_tick=tick)
        reach = max(_overlap(p) for p in poses)
        if with_mask:
            assert reach <= 0.01, f"the footprint reached {reach:.3f} m into the zone"
            assert max(p[0] for p in poses) > 1.4  # it drove up to the zone (and looked for a way round: none)
            assert not any(p[0] > 2.6 and p[1] > 2.6 for p in poses)
        else:
            assert poses[-1][0] > 4.5  # through the zone to the plan's end


def test_the_drive_manager_stops_any_input_at_a_keepout_zone_and_lets_a_robot_inside_out(mask):
    from emos.actors.nav.stacks import COMMAND_INPUTS

    forward = M.Twist(linear=M.Vector3(x=0.3))

    def drive(start, command: M.Twist, keepout: str, seconds: float = 6.0, topic: str = "/control/behaviors"):
        base = RoomBase(start=start)
        poses = []
        driver = _driver(loop_rate=20.0, command_inputs=COMMAND_INPUTS, keepout_mask=keepout)

        def tick(h: ComponentHarness) -> None:
            base(h)
            h.feed(topic, command)
            poses.append(base.pose.copy())

        with ComponentHarness(driver, start_time=10.0) as h:
            h.advance(seconds, each_tick=tick)
            return poses, h.health

    # A recovery behavior driving east along y 3.3, straight at the zone.
    poses, health = drive((1.0, 3.3, 0.0), forward, mask)
    assert max(_overlap(p) for p in poses) <= 0.01 and poses[-1][0] > 1.5
    assert health.is_algorithm_fail and "keepout zone 'wet_floor' (keepout.yaml)" in health.message
    # Backing into it (facing west, reversing east) is stopped as well.
    poses, _ = drive((1.0, 3.3, math.pi), M.Twist(linear=M.Vector3(x=-0.3)), mask)
    assert max(_overlap(p) for p in poses) <= 0.01 and poses[-1][0] > 1.5
    # Without the mask the same command drives through.
    poses, _ = drive((1.0, 3.3, 0.0), forward, "")
    assert poses[-1][0] > 2.6
    # A robot inside the zone (drawn under it) drives out.
    poses, health = drive((2.3, 3.3, math.pi), forward, mask, seconds=3.0)
    assert poses[-1][0] < 2.0 - RADIUS and not health.is_algorithm_fail


def test_use_zones_puts_the_masks_on_the_planner_controller_and_drive_manager(mask, tmp_path):
    from emos import Topic
    from emos.actors.nav import RobotFrames
    from emos.actors.nav.costmap import FilterMaskError
    from emos.actors.nav.stacks import point_navigation_stack
    from tests.nav.components.fake_base import write_room_map

    stack = point_navigation_stack(_robot(), RobotFrames(world="map", odom="map"), write_room_map(tmp_path / "room.yaml"),
                                   odom=Topic(name="/odom", msg_type="Odometry"), command=Topic(name="/cmd_vel", msg_type="Twist"))
    stack.use_zones(keepout_mask=mask)
    assert stack.planner.config.costmap.keepout_mask == stack.controller.config.keepout_mask == stack.driver.config.keepout_mask == mask
    with pytest.raises(FilterMaskError, match="nope.yaml"):
        stack.use_zones(keepout_mask=str(tmp_path / "nope.yaml"))
    from emos.actors.nav.components import DriveManagerConfig

    with pytest.raises(ValueError, match="keepout_mask .* is kept by the swept check; set swept_check=True"):
        DriveManagerConfig(keepout_mask=mask, swept_check=False)
