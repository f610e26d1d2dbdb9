"""A Controller whose ``local_map`` is a world-frame grid (an obstacle memory, a map) places its
cells by the grid's own origin, whatever pose the robot is read at: what the BARN stack relies
on (the ego-centric local map, placed with the controller's latest pose, lands a scan's motion
away when that pose is one scan older than the map)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import msgs as M
from emos.actors.nav.components.convert import BadInput, grid_msg, grid_points_in_robot_frame

pytestmark = pytest.mark.unit


def _world_grid(cells: list[tuple[int, int]], origin: tuple[float, float, float]) -> M.OccupancyGrid:
    data = np.zeros((20, 30), dtype=np.int8)
    for row, col in cells:
        data[row, col] = 100
    return grid_msg(data, 0.1, origin, "map")


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (-2.0, 1.5, 0.0), (1.0, -1.0, math.pi / 6)])
@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (1.2, 0.7, 0.9), (-0.5, 2.0, -2.5)])
def test_occupied_cells_of_a_world_grid_land_where_the_world_has_them(origin, pose):
    msg = _world_grid([(3, 4), (10, 25), (19, 0)], origin)
    got = grid_points_in_robot_frame(msg, np.array(pose))
    ox, oy, oyaw = origin
    want = []
    for row, col in [(3, 4), (10, 25), (19, 0)]:  # cell centres in the grid frame, to the world, to the robot
        gx, gy = (col + 0.5) * 0.1, (row + 0.5) * 0.1
        wx = ox + math.cos(oyaw) * gx - math.sin(oyaw) * gy
        wy = oy + math.sin(oyaw) * gx + math.cos(oyaw) * gy
        dx, dy = wx - pose[0], wy - pose[1]
        want.append((math.cos(pose[2]) * dx + math.sin(pose[2]) * dy, -math.sin(pose[2]) * dx + math.cos(pose[2]) * dy))
    order = np.lexsort(np.asarray(want).T)
    np.testing.assert_allclose(got[np.lexsort(got.T)], np.asarray(want)[order], atol=1e-9)


def test_the_points_follow_the_world_not_the_robot():
    # The same world grid read at two poses: the points move with the robot's pose exactly as
    # world-fixed obstacles do (back in the world frame they coincide).
    msg = _world_grid([(5, 5), (6, 7)], (0.0, 0.0, 0.0))
    back = []
    for pose in ((0.0, 0.0, 0.0), (0.04, 0.01, 0.05)):  # one lock-step scan of motion apart
        p = grid_points_in_robot_frame(msg, np.array(pose))
        c, s = math.cos(pose[2]), math.sin(pose[2])
        back.append(np.c_[pose[0] + c * p[:, 0] - s * p[:, 1], pose[1] + s * p[:, 0] + c * p[:, 1]])
    np.testing.assert_allclose(back[0], back[1], atol=1e-12)


def test_a_grid_whose_cells_do_not_match_its_size_is_refused():
    msg = _world_grid([], (0.0, 0.0, 0.0))
    msg.info.width = 31
    with pytest.raises(BadInput, match="local_map: 31x20 grid with 600 cells"):
        grid_points_in_robot_frame(msg, np.zeros(3))


def _controller_with_location(msg, **config):
    from emos.actors.nav.components import Controller, ControllerConfig

    class Reading(Controller):  # the location input as the node would hand it over
        location = msg

        def latest(self, key):
            return self.location if key == "location" else None

    return Reading("controller", config=ControllerConfig(use_direct_sensor=False, **config))


def _odometry(age_s: float, vx: float, wz: float):
    from emos.core import clock

    msg = M.Odometry(header=M.Header(stamp=M.Time.from_sec(clock.now() - age_s), frame_id="map"))
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = vx, wz
    return msg


def test_the_pose_is_carried_forward_over_its_age_with_the_measured_twist(monkeypatch):
    from emos.core import clock

    monkeypatch.setattr(clock, "now", lambda: 1000.0)  # the clock stands: the age is the stamp's, not the machine's pace
    pose, velocity = np.array([1.0, 2.0, 0.5]), np.array([2.0, 0.0, 1.0])
    controller = _controller_with_location(None)
    controller.location = _odometry(0.05, 2.0, 1.0)
    got = controller.predicted_pose(pose, velocity)
    # 0.05 s of a 2 m/s, 1 rad/s arc: a chord of 2 * (2 / 1) * sin(0.025) m, 0.05 rad of turn.
    assert math.dist(got[:2], pose[:2]) == pytest.approx(4.0 * math.sin(0.025), abs=1e-6)
    assert got[2] - pose[2] == pytest.approx(0.05, abs=1e-6)
    heading = math.atan2(got[1] - pose[1], got[0] - pose[0])
    assert abs(heading - (0.5 + (got[2] - 0.5) / 2)) < 1e-6  # a chord of the arc: half the turn


@pytest.mark.parametrize("age, horizon", [(-0.05, 0.2), (0.5, 0.2), (0.05, 0.0)])
def test_a_pose_of_another_clock_or_too_old_or_prediction_off_is_used_as_it_is(age, horizon, monkeypatch):
    from emos.core import clock

    monkeypatch.setattr(clock, "now", lambda: 1000.0)  # a slow construction must not age a stamp from the future
    pose = np.array([1.0, 2.0, 0.5])
    controller = _controller_with_location(_odometry(age, 2.0, 1.0), pose_prediction=horizon)
    assert controller.predicted_pose(pose, np.array([2.0, 0.0, 1.0])) is pose


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1.0, -1.0, math.pi / 6), (-3.0, 2.0, -2.0)])
def test_reading_within_a_range_is_the_full_grid_cut_to_that_range(origin):
    # Only the square of cells around the robot is looked at: the same points as reading the
    # whole grid and keeping those within range, wherever the robot is (inside, at an edge,
    # outside the grid) and however the grid is turned.
    rng = np.random.default_rng(3)
    cells = [tuple(x) for x in np.c_[rng.integers(0, 20, 150), rng.integers(0, 30, 150)]]
    msg = _world_grid(cells, origin)
    for pose in rng.uniform([-4.0, -4.0, -3.0], [5.0, 5.0, 3.0], (40, 3)):
        full = grid_points_in_robot_frame(msg, pose)
        for max_range in (0.35, 1.0, 2.5):
            want = full[np.hypot(full[:, 0], full[:, 1]) <= max_range]
            got = grid_points_in_robot_frame(msg, pose, max_range)
            np.testing.assert_allclose(got[np.lexsort(got.T)], want[np.lexsort(want.T)], atol=1e-9)
