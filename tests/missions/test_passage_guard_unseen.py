"""The passage guard's ``unseen_wait`` on robot time (``emos.testing.ComponentHarness``): a person
walked across the room (the band) and out of the scan's view; later the robot's plan crosses
the band with nobody in view or seen within ``out_of_view``. With ``unseen_wait`` the Behaviors
hold the robot at the band's edge that long for someone to come into view, once per way in, and
then let it go; without, it goes at once (the patrol's "no mover" entries, docs/missions.md)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import msgs as M
from emos.testing import ComponentHarness
from tests.nav.components.fake_base import base_messages

pytestmark = pytest.mark.unit

ROBOT = (2.0, 2.2, math.pi / 2)  # in fake_base's 6 x 4 m room, facing the band, 0.45 m before its edge
HALF = 0.15  # the person: a 0.3 m box


def _behaviors(unseen_wait: float):
    from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
    from emos.io.topic import Topic

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.2, 0.3]))
    behaviors = Behaviors("behaviors", config=BehaviorsConfig(
        robot=robot, loop_rate=10.0, frames=RobotFrames(world="map", odom="map"),
        passage_guard={"enabled": True, "out_of_view": 2.0, "unseen_wait": unseen_wait}))
    behaviors.inputs(plan=Topic(name="/plan", msg_type="Path"))
    return behaviors


def _run(unseen_wait: float, person_back_at: float | None = None) -> tuple[dict, list[float]]:
    """The person walks y = 3.2 from x = 0.5 at 0.6 m/s for 6 s, then is out of view; from t = 10
    s the plan crosses the band. ``person_back_at``: the person walks the same way again from then.
    Returns the stats and the harness times at which a hold was running."""
    from emos.actors.nav.components.convert import path_msg

    behaviors = _behaviors(unseen_wait)
    person = np.array([0.5, 3.2])
    held_at: list[float] = []
    plan = np.array([(2.0, y, math.pi / 2) for y in np.arange(2.2, 3.81, 0.05)])

    def world(h: ComponentHarness) -> None:
        back = person_back_at is not None and h.time >= person_back_at
        in_view = h.time < 6.0 or back
        if in_view:  # from x = 0.5 towards the robot's crossing at x = 2 and on, each time
            person[0] = 0.5 + 0.6 * (h.time - person_back_at if back else h.time)
        boxes = [(person[0] - HALF, person[1] - HALF, person[0] + HALF, person[1] + HALF)] if in_view else []
        odom, scan = base_messages(ROBOT, 0.0, 0.0, 2 * math.pi, boxes)
        odom.header.stamp = scan.header.stamp = M.Time.from_sec(h.time)
        h.feed("/odom", odom)
        h.feed("/scan", scan)
        if h.time >= 10.0:
            h.feed("/plan", path_msg(plan, "map"))
        running = behaviors._running
        if running is not None and running.name == "hold_passage" and running.result is None:
            held_at.append(h.time)

    with ComponentHarness(behaviors, tick=0.1) as h:
        h.advance(30.0, each_tick=world)
        stats = behaviors.stats()
    return stats, held_at


def test_with_unseen_wait_the_robot_waits_at_the_edge_for_someone_to_come_into_view_then_goes():
    stats, held = _run(unseen_wait=5.0)
    assert stats["passage_hold"] == 1, stats  # one wait at this edge, not one after another
    assert held and held[0] >= 10.0 and 5.0 <= held[-1] - held[0] <= 7.0, (held[:1], held[-1:])
    assert stats["passage_hold_given_up"] == 0


def test_without_unseen_wait_the_robot_goes_in_when_nobody_is_known():
    stats, held = _run(unseen_wait=0.0)
    assert stats["passage_hold"] == 0, stats


def test_a_person_coming_into_view_during_the_wait_is_judged_as_usual():
    # The person is back in view at t = 12 s at x = 0.5, walking the band towards the robot's
    # crossing at x = 2: the hold goes on past the 5 s wait (t = 15) while the person would meet
    # the robot, until they are past.
    stats, held = _run(unseen_wait=5.0, person_back_at=12.0)
    assert stats["passage_hold"] >= 1, stats
    assert held and held[0] >= 10.0 and held[-1] >= 16.0, (held[:1], held[-1:])
