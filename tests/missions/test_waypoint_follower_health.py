"""The WaypointFollower on the component harness: a missed waypoint is the component's news (an
ALGORITHM failure naming it, logged once) until the mission reaches its next waypoint; it does not
stay failed for the rest of a long patrol."""
from __future__ import annotations

import logging

import pytest

from emos.actors.nav.components.waypoints import WaypointFollower, WaypointFollowerConfig
from emos.msgs.nav import Odometry
from emos.msgs.std import Bool
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit


def _odom(x: float, y: float) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = "map"
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.w = 1.0
    return msg


def test_a_missed_waypoint_fails_the_health_until_the_next_is_reached_and_is_logged_once(caplog):
    follower = WaypointFollower("waypoints", config=WaypointFollowerConfig(stop_on_failure=False, waypoint_timeout=5.0))
    with ComponentHarness(follower, tick=0.2) as h, caplog.at_level(logging.WARNING):
        h.feed("/odom", _odom(0.0, 0.0))
        assert follower.start_mission([(3.0, 0.0), (0.5, 0.0), (4.0, 0.0)])
        h.advance(4.0)
        assert follower.health_status.is_healthy
        h.advance(2.0)  # waypoint 0 not reached within 5 s: missed, the mission goes on to waypoint 1
        assert follower.health_status.is_algorithm_fail and "missed waypoint 0" in follower.health_status().message
        h.advance(3.0)  # still on the way to waypoint 1 (15 steps): the miss is still the news
        assert follower.health_status.is_algorithm_fail and "missed waypoint 0" in follower.health_status().message
        misses = [r for r in caplog.records if "missed waypoint 0" in r.getMessage()]
        assert len(misses) == 1, [r.getMessage() for r in misses]
        h.feed("/odom", _odom(0.45, 0.0))
        h.feed("/reached_end", Bool(data=True))
        h.advance(1.0)  # waypoint 1 reached: healthy again, the miss stays in the mission's record
        assert follower.health_status.is_healthy
        assert follower._mission is not None and [i for i, _ in follower._mission.missed] == [0]
