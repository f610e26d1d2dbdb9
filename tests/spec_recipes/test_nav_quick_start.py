"""The Webots quick start (recipes/nav_quick_start.py, navigation/simulation-quickstarts.md) and the
point-navigation page's code (recipes/point_navigation_spec.py) run with ``emos run``: the web UI
comes up, and a point published on the map (the pages' "click anywhere on the map") brings the
robot there, the Simulator building the arena from the spec's ``turtlebot3_webots.yaml`` in
place of Webots. (The Gazebo quick start: tests/spec_maps/test_house_navigation.py.)"""
from __future__ import annotations

import math
import re
import socket

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = [pytest.mark.sim, pytest.mark.process]

COMPONENTS = ["sim", "global_map_server", "planner", "controller", "drive_manager", "mapper"]


@pytest.mark.parametrize("recipe", ["nav_quick_start.py", "point_navigation_spec.py"])
def test_the_webots_arena_stack_reaches_a_clicked_goal_and_serves_the_ui(tmp_path, recipe):
    from emos.transport.pubsub import Publisher, Subscriber

    source = (REPO / "recipes" / recipe).read_text()
    # the goal the recipe's docstring clicks (free space in the map: tests/spec_maps checks the recipes' goals)
    gx, gy = (float(v) for v in re.search(r'"x": ([-\d.]+), "y": ([-\d.]+)', source).groups())
    with socket.socket() as s:  # the page's UI port is 5001: a free one here, so runs side by side do not collide
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert source.count("launcher.enable_ui(") == 1
    source = source.replace("launcher.enable_ui(", f"launcher.enable_ui(port={port}, ")
    system = SystemUnderTest(tmp_path, source, env={"PYTHONPATH": str(REPO)}).wait_up(components=COMPONENTS + ["ui"])
    assert system.ctx is not None
    odom = Subscriber(system.ctx, "/odometry/filtered", M.Odometry, queue_size=50)
    reached = Subscriber(system.ctx, "/reached_end", M.Bool, queue_size=50)
    goal = Publisher(system.ctx, "/goal", M.PointStamped, publisher_id="test_click")
    try:
        import httpx

        url = wait_until(lambda: re.search(rf"EMOS UI: (http://\S+:{port}/\S*)", system.output()), 60, what="the UI's link")
        assert httpx.get(url.group(1), timeout=30, follow_redirects=True).status_code == 200  # the page, signed in
        click = M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=gx, y=gy))
        last: list = []

        def arrived() -> bool:
            goal.publish(click)  # a topic keeps no message for late subscribers: click until it is taken
            last.extend(odom.take()[-1:])
            return any(m.data for m in reached.take())

        wait_until(arrived, 180, interval=0.5, what=f"reached_end for the goal ({gx}, {gy})")
        last.extend(odom.take()[-1:])
        p = last[-1].pose.pose.position
        assert math.hypot(p.x - gx, p.y - gy) < 0.4, (p.x, p.y)
    finally:
        goal.close()
        odom.close()
        reached.close()
        system.stop()
