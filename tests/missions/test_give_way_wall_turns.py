"""A person turning a corner towards the robot, before any walk of theirs is remembered (the
patrol's first lap): the scan tracker's velocity is a fit over the last second, so while they
turn it still says they walk on into the wall. With the static map the give-way predicts a
straight line into a wall turning along it, either way (``WallFilter.turns``), and starts as
the person reaches the corner, not a second later; the passage guard holds the robot instead
of letting it in. On robot time (``emos.testing.ComponentHarness``) and on the house's corner."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.controllers.movers import WallFilter
from emos.actors.nav.maps import OccupancyGridMap, load_map
from emos.actors.nav.maps.map_yaml import save_map
from emos.testing import ComponentHarness
from tests.missions.person_scene import ROBOT_RADIUS, feed, gap
from tests.nav.components.fake_base import ROOM, CommandFollower

pytestmark = pytest.mark.unit

RES = 0.05
SPEED = 0.6
CORNER = np.array([2.0, 3.45])  # the person walks up x = 2 to here (0.55 m below the room's top wall), then east
ROBOT = (3.6, 3.45, math.pi)  # standing in the way east of the corner, facing it
START = 5.0
UP_FROM = 0.8  # y the person starts from


def _room_map(tmp_path) -> str:
    w, h = int(round((ROOM[2] + 0.5) / RES)), int(round((ROOM[3] + 0.5) / RES))
    data = np.zeros((h, w), dtype=np.int8)
    xs, ys = (np.arange(w) + 0.5) * RES - 0.25, (np.arange(h) + 0.5) * RES - 0.25
    gx, gy = np.meshgrid(xs, ys)
    data[(gx < ROOM[0]) | (gx > ROOM[2]) | (gy < ROOM[1]) | (gy > ROOM[3])] = 100
    return str(save_map(OccupancyGridMap(data=data, resolution=RES, origin=(-0.25, -0.25, 0.0)), tmp_path / "room.yaml"))


def walked(t: float) -> np.ndarray:
    up = CORNER[1] - UP_FROM
    s = max(t, 0.0) * SPEED
    return np.array([CORNER[0], UP_FROM + s]) if s <= up else CORNER + np.array([s - up, 0.0])


class Scene(CommandFollower):
    def __init__(self):
        super().__init__(ROBOT)
        self.person = walked(0.0)

    def __call__(self, h: ComponentHarness) -> None:
        v, w = self.move(h)
        self.person = walked(h.time - START)
        feed(h, self.pose, v, w, self.person)


def _give_way_start(static_map: str) -> tuple[float, float]:
    """(s after the person reached the corner, gap then) when the give-way started."""
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    behaviors = Behaviors("behaviors", config=BehaviorsConfig(robot=robot, loop_rate=10.0, max_rotational_vel=1.0,
                                                              give_way={"enabled": True}, static_map=static_map))
    scene = Scene()
    at_corner = START + (CORNER[1] - UP_FROM) / SPEED
    with ComponentHarness(behaviors, start_time=0.0) as h:
        while h.time < at_corner + 3.0:
            h.advance(0.1, each_tick=scene)
            if behaviors.stats()["give_way"]:
                return h.time - at_corner, gap(scene.pose, scene.person)
    return math.inf, math.nan


def test_a_person_turning_a_corner_at_the_robot_is_given_way_to_as_they_turn(tmp_path):
    late, late_gap = _give_way_start("")
    early, early_gap = _give_way_start(_room_map(tmp_path))
    assert early <= 0.2 and early + 0.4 <= late, (early, late)
    assert early_gap >= late_gap + 0.25, (early_gap, late_gap)


def test_turns_along_a_wall_either_way_and_not_into_the_corner(tmp_path):
    walls = WallFilter(load_map(_room_map(tmp_path)))
    times = np.arange(0.0, 3.01, 0.1)
    ways = walls.turns(np.array([3.0, 3.0]), np.array([0.0, 0.6]), 0.2, times)  # up at the top wall: east and west
    # Up to where the body (0.2 m) comes within 0.05 m of the wall (y = 4), then 1.7 s along it.
    assert sorted(round(float(w[-1][0] - 3.0), 1) for w in ways) == [-1.0, 1.0], [w[-1] for w in ways]
    assert all(3.7 <= float(w[-1][1]) <= 3.8 for w in ways)
    into_corner = walls.turns(np.array([5.6, 3.0]), np.array([0.0, 0.6]), 0.2, times)  # east runs into the east wall
    assert len(into_corner) == 1 and into_corner[0][-1][0] < 5.6
    short = walls.turns(np.array([5.3, 3.0]), np.array([0.0, 0.6]), 0.2, times)  # east: 0.45 m to the east wall, then stands
    assert len(short) == 2 and 5.7 <= max(float(w[-1][0]) for w in short) <= 5.8
    assert walls.turns(np.array([3.0, 1.0]), np.array([0.0, 0.6]), 0.2, times) == []  # 3 s do not reach the wall
    assert walls.turns(np.array([3.0, 3.0]), np.array([0.0, 0.1]), 0.2, times) == []  # slower than a walk


def test_the_guard_holds_the_robot_for_a_person_turning_the_corner_of_the_house_on_the_first_lap():
    """The house's person has walked up x = 4.2 (all that is remembered) and is at the corner
    under the corridor's wall, tracked still walking up; the robot waits in the corridor east of
    the corner to drive west through it (the patrol's right-to-left way, first lap). At constant
    velocity the person walks on into the wall and the guard lets the robot in (it then met the
    person coming east round the corner); with the map's walls it holds it."""
    import os

    import emos.actors.sim.data as data
    from emos.actors.nav.missions.passages import MoverMemory, PassageGuardConfig, check_passage

    memory = MoverMemory()
    for t in np.arange(0.0, 4.3, 0.1):
        memory.observe(float(t), np.array([[4.2, 0.75 + 0.6 * t]]), np.array([[0.0, 0.6]]))
    walls = WallFilter.from_map_file(os.path.join(os.path.dirname(data.__file__), "house.yaml"), 0.1)
    path = np.array([(5.2, 3.4), (4.0, 3.45), (3.0, 3.8), (2.5, 4.2)])
    args = (path, path[0], memory, 4.4, np.array([[4.26, 3.18]]), np.array([[-0.03, 0.63]]), np.array([0.22]), ROBOT_RADIUS,
            PassageGuardConfig(enabled=True))
    blind = check_passage(*args)
    assert blind.start is not None and not blind.hold, blind
    seeing = check_passage(*args, walls=walls)
    assert seeing.hold, seeing
