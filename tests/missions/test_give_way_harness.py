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



def _behaviors():
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    return Behaviors("behaviors", config=BehaviorsConfig(robot=robot, loop_rate=10.0, max_rotational_vel=1.0,
                                                         give_way={"enabled": True}))


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
