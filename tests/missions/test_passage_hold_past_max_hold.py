"""A passage hold at ``max_hold`` on robot time (``emos.testing.ComponentHarness``): a person walks
back and forth across the robot's way, always coming by again before the robot could be
through. A hold that gave up at ``max_hold`` whatever the guard said let the robot in while the
person was coming back (a twenty-lap patrol's contact); now a hold for a mover goes on until
the way has been clear for ``release_time``, as before ``max_hold``."""
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
WALK = (0.8, 3.2)  # x the person walks between on y = 3.2, at SPEED: past the robot's crossing (x = 2) every 2 s
SPEED = 0.6
PLAN_FROM = 20.0  # s: the person's walks are remembered by then; the robot's plan crosses the band


def _person_at(t: float) -> np.ndarray:
    span = WALK[1] - WALK[0]
    s = (t * SPEED) % (2 * span)
    return np.array([WALK[0] + (s if s <= span else 2 * span - s), 3.2])


def _run(stop_at: float | None, seconds: float = 40.0) -> tuple[dict, list[float], str]:
    """The person walks from t = 0 (stops for good at ``stop_at``, None: never); the plan from
    PLAN_FROM. Returns the stats, the times a hold ran and the last behavior result's message."""
    from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
    from emos.actors.nav.components.convert import path_msg
    from emos.io.topic import Topic

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.2, 0.3]))
    behaviors = Behaviors("behaviors", config=BehaviorsConfig(
        robot=robot, loop_rate=10.0, frames=RobotFrames(world="map", odom="map"),
        passage_guard={"enabled": True, "max_hold": 10.0}))
    behaviors.inputs(plan=Topic(name="/plan", msg_type="Path"))
    plan = np.array([(2.0, y, math.pi / 2) for y in np.arange(2.2, 3.81, 0.05)])
    held_at: list[float] = []
    stopped = None

    def world(h: ComponentHarness) -> None:
        nonlocal stopped
        if stop_at is not None and h.time >= stop_at:
            stopped = _person_at(stop_at) if stopped is None else stopped
        person = stopped if stopped is not None else _person_at(h.time)
        odom, scan = base_messages(ROBOT, 0.0, 0.0, 2 * math.pi,
                                   [(person[0] - HALF, person[1] - HALF, person[0] + HALF, person[1] + HALF)])
        odom.header.stamp = scan.header.stamp = M.Time.from_sec(h.time)
        h.feed("/odom", odom)
        h.feed("/scan", scan)
        if h.time >= PLAN_FROM:
            h.feed("/plan", path_msg(plan, "map"))
        running = behaviors._running
        if running is not None and running.name == "hold_passage" and running.result is None:
            held_at.append(h.time)

    with ComponentHarness(behaviors, tick=0.1) as h:
        h.advance(PLAN_FROM + seconds, each_tick=world)
        stats = behaviors.stats()
        last = behaviors.last_result
    return stats, held_at, last.message if last is not None else ""


def test_a_hold_holds_on_past_max_hold_while_a_walking_person_would_meet_the_robot():
    stats, held, _ = _run(stop_at=None)
    assert stats["passage_hold"] >= 1 and held and held[0] < PLAN_FROM + 2.0, (stats, held[:1])
    assert stats["passage_hold_given_up"] == 0, stats
    assert held[-1] - held[0] >= 30.0, (held[0], held[-1])  # three times max_hold, held all along
    assert stats["passage_hold"] == 1, stats


def test_past_max_hold_a_hold_ends_when_the_way_has_been_clear_for_release_time():
    """The person stops for good at the far end of their walk (x = 0.8) 28 s after the plan
    appears: the tracker loses a person standing still, and the guard predicts them walking on
    from where it last saw them for ``out_of_view`` (15 s), then no mover: the hold ends 1 s
    (``release_time``) later, done, not given up."""
    stop = PLAN_FROM + 28.0
    assert abs(_person_at(stop)[0] - WALK[0]) < 1e-6
    stats, held, message = _run(stop_at=stop, seconds=60.0)
    assert held and held[0] < PLAN_FROM + 2.0
    assert stop + 10.0 <= held[-1] <= stop + 20.0, held[-1]
    assert stats["passage_hold_given_up"] == 0 and message.startswith("hold_passage done") and "no mover" in message, (stats, message)
