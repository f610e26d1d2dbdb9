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


def _run(stop_at: float | None, seconds: float = 40.0, person_at=None, max_hold: float = 10.0,
         ended: list | None = None) -> tuple[dict, list[float], str]:
    """The person walks from t = 0 (stops for good at ``stop_at``, None: never), or is where
    ``person_at(t)`` says (None: out of view); the plan from PLAN_FROM. Returns the stats, the
    times a hold ran and the last behavior result's message; ``ended`` gets (time, message) of
    each hold that ended."""
    from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
    from emos.actors.nav.components.convert import path_msg
    from emos.io.topic import Topic

    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.2, 0.3]))
    behaviors = Behaviors("behaviors", config=BehaviorsConfig(
        robot=robot, loop_rate=10.0, frames=RobotFrames(world="map", odom="map"),
        passage_guard={"enabled": True, "max_hold": max_hold}))
    behaviors.inputs(plan=Topic(name="/plan", msg_type="Path"))
    plan = np.array([(2.0, y, math.pi / 2) for y in np.arange(2.2, 3.81, 0.05)])
    held_at: list[float] = []
    stopped = None

    def world(h: ComponentHarness) -> None:
        nonlocal stopped
        if stop_at is not None and h.time >= stop_at:
            stopped = _person_at(stop_at) if stopped is None else stopped
        person = stopped if stopped is not None else (person_at or _person_at)(h.time)
        boxes = [] if person is None else [(person[0] - HALF, person[1] - HALF, person[0] + HALF, person[1] + HALF)]
        odom, scan = base_messages(ROBOT, 0.0, 0.0, 2 * math.pi, boxes)
        odom.header.stamp = scan.header.stamp = M.Time.from_sec(h.time)
        h.feed("/odom", odom)
        h.feed("/scan", scan)
        if h.time >= PLAN_FROM:
            h.feed("/plan", path_msg(plan, "map"))
        running = behaviors._running
        if running is not None and running.name == "hold_passage" and running.result is None:
            held_at.append(h.time)
        last = behaviors.last_result
        if ended is not None and last is not None and last.message.startswith("hold_passage") and \
                (not ended or ended[-1][1] != last.message):
            ended.append((h.time, last.message))

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


DOOR = WALK[0]  # x of the door the person leaves the view through: where they otherwise turn
AWAY = 9.0  # s out of view beyond the door each time, then back the same way
ROUNDS = 2  # walks back and forth past the robot's way (WALK) between the times through the door
_ROUND = 2 * (WALK[1] - WALK[0]) / SPEED
_TO_DOOR = (WALK[0] - DOOR) / SPEED


def _pacing(t: float, away: float = AWAY) -> np.ndarray | None:
    """Back and forth past the robot's way ROUNDS times (the first test's walk), then out through
    the door and AWAY s out of view, and back in: None while out of view."""
    s = t % (ROUNDS * _ROUND + 2 * _TO_DOOR + away)
    if s < ROUNDS * _ROUND:
        return _person_at(s)
    s -= ROUNDS * _ROUND
    if s < _TO_DOOR:
        return np.array([WALK[0] - SPEED * s, 3.2])
    if s < _TO_DOOR + away:
        return None
    return np.array([DOOR + SPEED * (s - _TO_DOOR - away), 3.2])


def test_past_max_hold_a_hold_gives_up_just_after_a_person_with_no_known_walk_left_the_view():
    """A person walks back and forth past the robot's way and out of view through a door for 9 s,
    over and over: in view they would meet the robot, out of view their walk from the door is not
    known (the patrol's person on its first lap, at the corridor's corner), so a hold that began
    while they were out of view or coming would never end. Past ``max_hold`` (3 s here) the hold
    gives up, and only in the moment the person has just left the view walking away (the most
    time before they are back): never while they are in view or have been out of it for long."""
    exits = [(ROUNDS * _ROUND + 2 * _TO_DOOR + AWAY) * k + ROUNDS * _ROUND + _TO_DOOR for k in range(8)]
    ended: list = []
    stats, held, _ = _run(stop_at=None, seconds=60.0, person_at=_pacing, max_hold=3.0, ended=ended)
    given_up = [(t, m) for t, m in ended if m.startswith("hold_passage gave up")]
    assert given_up and stats["passage_hold_given_up"] == len(given_up), (stats, ended)
    for t, message in given_up:
        assert any(0.5 <= t - e <= 2.0 for e in exits), (t, exits, message)
        assert "just left the view" in message, message


def test_past_max_hold_a_person_who_came_back_sooner_than_the_drive_through_is_waited_for():
    """The same person, out of view for 3 s each time: shorter than the robot takes to drive
    through (5 s), so the moment they leave is no window and the hold goes on, not given up."""
    ended: list = []
    stats, held, _ = _run(stop_at=None, seconds=60.0, person_at=lambda t: _pacing(t, away=3.0), max_hold=3.0, ended=ended)
    assert stats["passage_hold"] >= 1 and stats["passage_hold_given_up"] == 0, (stats, ended)
