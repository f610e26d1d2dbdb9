"""One navigation run in the spec's Gazebo house map (issue 33 item 3): recipes/nav_quick_start_gz.py,
the Gazebo quick start's stack and robot (a TurtleBot3 Waffle Pi: a 0.3 x 0.3 m box, 0.26 m/s), with the Simulator building
the house from ``turtlebot3_gazebo_house.yaml`` in place of Gazebo, drives from kompass_sim's spawn
in the hall through the doorway into the right wing, a goal a user clicks on the map."""
from __future__ import annotations

import math

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

GOAL = (4.5, 1.5)  # the right wing, through the 0.9 m doorway at x = 2.3

# The spec's quick_start_gz.py with its imports, command type and simulator lines changed.
STACK = (REPO / "recipes" / "nav_quick_start_gz.py").read_text()

COMPONENTS = ["sim", "global_map_server", "planner", "controller", "drive_manager", "mapper"]


def test_the_gazebo_quick_start_stack_reaches_a_clicked_goal_in_the_house(tmp_path):
    from emos.core import control
    from emos.transport.pubsub import Publisher, Subscriber

    system = SystemUnderTest(tmp_path, STACK, env={"PYTHONPATH": str(REPO)}).wait_up(components=COMPONENTS)
    assert system.ctx is not None
    odom = Subscriber(system.ctx, "/odometry/filtered", M.Odometry, queue_size=50)
    reached = Subscriber(system.ctx, "/reached_end", M.Bool, queue_size=50)
    goal = Publisher(system.ctx, "/goal", M.PointStamped, publisher_id="test_click")
    try:
        click = M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=GOAL[0], y=GOAL[1]))
        last: list = []

        def arrived() -> bool:
            goal.publish(click)  # a topic keeps no message for late subscribers: click until it is taken
            last.extend(odom.take()[-1:])
            return any(m.data for m in reached.take())

        # Bounds a hang only: the drive is about 5 m at 0.26 m/s.
        wait_until(arrived, 180, interval=0.5, what="reached_end for the goal in the right wing")
        last.extend(odom.take()[-1:])
        p = last[-1].pose.pose.position
        assert math.hypot(p.x - GOAL[0], p.y - GOAL[1]) < 0.4
        status = control.ControlClient("sim", system.ctx, timeout=10.0).execute_method("sim_status")
        assert status["collided"] is False
    finally:
        goal.close()
        odom.close()
        reached.close()
        system.stop()
