"""The Behaviors' give-way on robot time (``emos.testing.ComponentHarness``): a kinematic base
drives by the component's commands and scans a blind person walking straight at where the robot
stood. The give-way may only hand back once the robot, standing where the move left it, is out
of the person's way: a yield move still under way is not a clear way (under load, the sim test
saw a hand-back 2.4 s into a pull-aside, and the person walked into the stopped robot)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.testing import ComponentHarness
from tests.missions.person_scene import HALF, ROBOT_RADIUS, feed, gap
from tests.nav.components.fake_base import CommandFollower

pytestmark = pytest.mark.unit



def _behaviors(**config):
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    return Behaviors("behaviors", config=BehaviorsConfig(robot=robot, loop_rate=10.0, max_rotational_vel=1.0,
                                                         give_way={"enabled": True}, **config))


class PersonAndBase(CommandFollower):
    """Before every tick: the base moves by the newest command, the person walks on (blind)."""

    def __init__(self, robot, person, velocity):
        super().__init__(robot)
        self.person, self.velocity = np.array(person, float), np.array(velocity, float)
        self.least = math.inf
        self.handed_back: list[tuple[float, np.ndarray, np.ndarray]] = []  # (time, robot pose, person centre)

    def __call__(self, h: ComponentHarness) -> None:
        last = h.time if self.last_time is None else self.last_time
        v, w = self.move(h)
        self.person = self.person + self.velocity * (h.time - last)
        self.least = min(self.least, gap(self.pose, self.person))
        feed(h, self.pose, v, w, self.person)


def test_give_way_hands_back_only_when_the_standing_robot_is_out_of_the_persons_way():
    world = PersonAndBase(robot=(2.0, 2.0, 0.0), person=(5.2, 2.0), velocity=(-0.4, 0.0))
    behaviors = _behaviors()
    with ComponentHarness(behaviors, start_time=5.0) as h:
        done = 0
        while world.person[0] > 0.6 and h.time < 30.0:
            h.advance(0.1, each_tick=world)
            stats = behaviors.stats()
            if stats["succeeded"] > done:  # a give-way handed back this step
                done = stats["succeeded"]
                world.handed_back.append((h.time, world.pose.copy(), world.person.copy()))
        stats = behaviors.stats()
    assert stats["give_way"] >= 1, stats  # it saw the person coming and gave way
    assert world.least > 0.0, f"the person walked into the robot (least gap {world.least:.3f} m)"
    for t, robot, person in world.handed_back:
        passed = person[0] + HALF < robot[0] - ROBOT_RADIUS
        aside = abs(robot[1] - person[1]) > HALF + ROBOT_RADIUS
        assert passed or aside, f"handed back at t={t:.1f} s with the robot at {robot} in the way of the person at {person}"


def _yield_after_a_forgotten_walk(band_memory: float) -> tuple[np.ndarray, float]:
    """A person walks along y = 1 (1 m to the robot's right) and leaves; 20 s past the guard's
    ``memory`` (20 s), another walks head-on at the robot standing at (2, 2). Returns where the
    give-way left the robot and the least gap to the second person."""
    behaviors = _behaviors(passage_guard={"enabled": True, "memory": 20.0, "band_memory": band_memory})
    base = CommandFollower((2.0, 2.0, 0.0))
    person, velocity = np.array([0.4, 1.0]), np.array([0.8, 0.0])
    least = math.inf

    def tick(h: ComponentHarness) -> None:
        nonlocal person, velocity, least
        last = h.time if base.last_time is None else base.last_time
        v, w = base.move(h)
        person = person + velocity * (h.time - last)
        if velocity[0] > 0 and person[0] > 5.6:  # out of the room: out of view
            person, velocity = np.array([50.0, 50.0]), np.zeros(2)
        elif velocity[0] == 0 and h.time > 45.0:  # 40 s after the walk began: the guard forgot it
            person, velocity = np.array([5.6, 2.0]), np.array([-0.5, 0.0])
        if velocity[0] < 0:
            least = min(least, gap(base.pose, person))
        feed(h, base.pose, v, w, person)

    with ComponentHarness(behaviors, start_time=5.0) as h:
        while h.time < 65.0 and not (velocity[0] < 0 and person[0] < 0.5):
            h.advance(0.1, each_tick=tick)
        assert behaviors.stats()["give_way"] >= 1, behaviors.stats()
    return base.pose, least


def test_a_yield_move_keeps_out_of_a_walk_the_guard_no_longer_predicts_from():
    """The guard predicts from walks of the last ``memory`` s; the give-way's yield moves keep
    out of the band walked in the last ``band_memory`` s (the patrol: a robot held for minutes
    where it could not see the person's walk down the next room pulled aside onto it)."""
    clearance = 0.55  # PassageGuardConfig.band_clearance
    pose, least = _yield_after_a_forgotten_walk(band_memory=900.0)
    assert abs(pose[1] - 1.0) > clearance, f"the yield move ended at {pose} in the band walked along y = 1"
    assert least > 0.0, f"the person walked into the robot (least gap {least:.3f} m)"
    # The same scene remembering the band only as long as the walks: the move ends in the band
    # (the scene tests what it says).
    forgot, _ = _yield_after_a_forgotten_walk(band_memory=20.0)
    assert abs(forgot[1] - 1.0) < clearance, f"the scene no longer leads a give-way into the band: ended at {forgot}"
