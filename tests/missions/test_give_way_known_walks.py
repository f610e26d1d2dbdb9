"""The give-way and the passage guard's memory (``PassageGuardConfig.known_walks``) on robot time
(``emos.testing.ComponentHarness``): a blind person walks an L back and forth, along y = 3 towards
a robot standing 1.2 m beyond the corner, then away down x = 3.6. At the corner their straight
line runs into the robot, so the give-way alone backs it out of the way on every pass; the robot
waiting at a passage's edge was so pushed out of its place each time the person came by (ten-lap
patrols in the house). With the memory of the person's earlier walks, which all turned at the
corner, a person walking as they did is not given way to; one who walks on past the corner at the
robot is, in time."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.testing import ComponentHarness
from tests.missions.person_scene import ROBOT_RADIUS, feed, gap
from tests.nav.components.fake_base import CommandFollower

pytestmark = pytest.mark.unit

WALK = np.array([(5.6, 3.0), (3.6, 3.0), (3.6, 0.4)])  # the L, walked back and forth at SPEED
SPEED = 0.6
ROBOT = (2.4, 3.0, 0.0)  # 1.2 m beyond the corner, facing it
SEG = np.hypot(*np.diff(WALK, axis=0).T)
LENGTH = float(SEG.sum())
PERIOD = 2 * LENGTH / SPEED


def walked(t: float) -> np.ndarray:
    """The person's centre at ``t`` s on the L (pingpong from WALK[0])."""
    s = (t * SPEED) % (2 * LENGTH)
    s = 2 * LENGTH - s if s > LENGTH else s
    k = 0 if s <= SEG[0] else 1
    s -= 0.0 if k == 0 else SEG[0]
    return WALK[k] + (WALK[k + 1] - WALK[k]) / SEG[k] * s


def _behaviors(known_walks: bool):
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    return Behaviors("behaviors", config=BehaviorsConfig(robot=robot, loop_rate=10.0, max_rotational_vel=1.0,
                                                         give_way={"enabled": True},
                                                         passage_guard={"enabled": True, "known_walks": known_walks}))


class Scene(CommandFollower):
    """Before every tick: the person walks (``path(t)``), the base moves by the newest command
    unless ``anchored`` (a robot held where it stands: each pass is then judged from the same
    place), both are scanned."""

    def __init__(self, path, anchored: bool):
        super().__init__(ROBOT)
        self.path, self.anchored = path, anchored
        self.person = path(0.0)
        self.least = math.inf

    def __call__(self, h: ComponentHarness) -> None:
        v, w = (0.0, 0.0) if self.anchored else self.move(h)
        self.person = self.path(h.time - START)
        self.least = min(self.least, gap(self.pose, self.person))
        feed(h, self.pose, v, w, self.person)


START = 5.0


def _give_ways_per_pass(known_walks: bool, passes: int = 4, path=walked, period: float = PERIOD,
                        robot=ROBOT) -> tuple[list[int], dict, float]:
    """Give-ways started during each pass of the person (one ``period`` of ``path``), the robot
    anchored at ``robot``; the stats and the least gap at the end."""
    behaviors = _behaviors(known_walks)
    scene = Scene(path, anchored=True)
    scene.pose = np.array(robot, dtype=float)
    counts = []
    with ComponentHarness(behaviors, start_time=START) as h:
        for k in range(passes):
            before = behaviors.stats()["give_way"]
            while h.time < START + (k + 1) * period:
                h.advance(0.1, each_tick=scene)
            counts.append(behaviors.stats()["give_way"] - before)
        return counts, behaviors.stats(), scene.least


def test_a_person_walking_as_before_past_a_waiting_robot_is_not_given_way_to():
    without, _, _ = _give_ways_per_pass(known_walks=False)
    assert all(n >= 1 for n in without), without  # the straight line at the corner meets the robot on every pass
    known, stats, _ = _give_ways_per_pass(known_walks=True)
    assert known[0] >= 1, known  # nothing remembered yet on the first pass
    assert known[2:] == [0, 0], known  # walks remembered (2 s old at least): the person turns at the corner, as before
    assert stats["known_walks_spared"] >= 2, stats


def test_a_person_who_walks_on_past_the_corner_at_the_robot_is_given_way_to_in_time():
    """Three passes as before, then on the way along y = 3 the person walks straight on past the
    corner at the robot (and on to x = 0.5): the remembered walks no longer match once they are
    past the corner, and the give-way takes the robot out of the way."""
    turn_back = 3 * PERIOD  # the start of the fourth pass: at WALK[0], walking towards the corner

    def deviating(t: float) -> np.ndarray:
        if t < turn_back:
            return walked(t)
        return np.array([max(WALK[0][0] - SPEED * (t - turn_back), 0.5), WALK[0][1]])

    behaviors = _behaviors(known_walks=True)
    scene = Scene(deviating, anchored=False)
    with ComponentHarness(behaviors, start_time=START) as h:
        while h.time < START + turn_back:
            h.advance(0.1, each_tick=scene)
        scene.least = math.inf
        before = behaviors.stats()["give_way"]
        while h.time < START + turn_back + 12.0:
            h.advance(0.1, each_tick=scene)
        stats = behaviors.stats()
    assert stats["give_way"] > before, stats
    assert scene.least > 0.0, f"the person walked into the robot (least gap {scene.least:.3f} m)"


# A robot standing beside the end of a person's walk (a passage hold at the walk's end, the
# patrol's right-to-left crossing): the person comes within near_distance where they turn round.
END_WALK = np.array([(5.6, 3.0), (3.0, 3.0)])
BESIDE_THE_END = (3.0, 2.28, math.pi / 2)  # 0.37 m from the person's box where they turn


def along_end_walk(t: float) -> np.ndarray:
    span = float(END_WALK[0][0] - END_WALK[1][0])
    s = (t * SPEED) % (2 * span)
    return np.array([END_WALK[0][0] - (s if s <= span else 2 * span - s), 3.0])


END_PERIOD = 2 * float(END_WALK[0][0] - END_WALK[1][0]) / SPEED


def test_a_person_turning_near_a_standing_robot_as_before_is_not_given_way_to():
    beside = {"path": along_end_walk, "period": END_PERIOD, "robot": BESIDE_THE_END}
    without, _, _ = _give_ways_per_pass(known_walks=False, **beside)
    assert all(n >= 1 for n in without), without  # near_distance: on every turn at the end
    known, _, least = _give_ways_per_pass(known_walks=True, **beside)
    assert known[2:] == [0, 0], known  # every earlier walk turned there, clear of the robot
    assert least > 0.2, least


def test_a_person_who_walks_at_a_standing_robot_from_the_end_of_their_walk_is_given_way_to():
    """Three passes as before, then at the end of the walk the person turns down, at the robot:
    off the remembered walks, the give-way starts at once."""
    turn_down = 3 * END_PERIOD - END_PERIOD / 2  # at the end of the walk, (3.0, 3.0)

    def deviating(t: float) -> np.ndarray:
        if t < turn_down:
            return along_end_walk(t)
        return np.array([3.0, max(3.0 - SPEED * (t - turn_down), 0.5)])

    behaviors = _behaviors(known_walks=True)
    scene = Scene(deviating, anchored=True)  # held where it waits until the person turns at it
    scene.pose = np.array(BESIDE_THE_END)
    started_at = None
    with ComponentHarness(behaviors, start_time=START) as h:
        while h.time < START + turn_down:
            h.advance(0.1, each_tick=scene)
        scene.anchored = False
        before = behaviors.stats()["give_way"]
        while h.time < START + turn_down + 6.0:
            h.advance(0.1, each_tick=scene)
            if started_at is None and behaviors.stats()["give_way"] > before:
                started_at = h.time - START - turn_down
    assert started_at is not None and started_at <= 0.5, started_at
