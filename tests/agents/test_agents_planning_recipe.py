"""recipes/planning_models.py end to end under ``emos run``, against the real local model server:
the command is parsed, the person grounded in the camera image with depth, the Planner's goal
lands on the person's true position in the simulated world, and the robot drives there."""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from tests.agents.components_helpers import Probe, sim_status
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPES = Path(__file__).resolve().parents[2] / "recipes"
GOAL_LINE = re.compile(r"\[planner\] goal from goal_point /grounding_output \(Detections\): \(([-\d.]+), ([-\d.]+)\)")


@pytest.fixture
def server():
    proc = start_server(script=str(RECIPES / "models" / "responder.yaml"))
    yield proc
    proc.stop()


def test_planning_models_recipe_grounds_the_person_and_drives_to_it(tmp_path, server):
    system = SystemUnderTest(tmp_path, (RECIPES / "planning_models.py").read_text(), duration=150,
                             env={"EMOS_MODELS_PORT": str(server.port), "HOME": str(tmp_path)})
    system.wait_up(components=["sim", "user", "sentence_parser", "go_to_x", "planner", "controller"], timeout=90)
    probe = Probe(system)
    try:
        odom, plans = probe.sub("/odom", "Odometry"), probe.sub("/plan", "Path")
        # The person's true place, from the running world (it walks 0.2 m into place, then stands).
        def person_standing():
            movers = sim_status(system).get("movers", [])
            return movers[0]["pose"][:2] if movers and sim_status(system)["sim_time"] > 2.0 else None

        person = wait_until(person_standing, 30, interval=0.5, what="the person in the world")
        start = wait_until(odom.latest, 30, what="odometry").pose.pose.position
        # 1. the LLM parsed the object; 2. the VLM grounded it, depth attached (the recipe's user reports)
        wait_until(lambda: "[user] sentence_parser: the object is 'person'" in system.output(), 45, interval=0.2,
                   what="the parsed object")
        wait_until(lambda: re.search(r"\[user\] go_to_x grounded it: \d+ box\(es\) \[[\d, ]+\]", system.output()), 30,
                   interval=0.2, what="the grounded box")
        assert "with the depth image" in system.output()
        # 3. the Planner's goal (its log, and the end of its plans) is on the person
        goal = wait_until(lambda: GOAL_LINE.search(system.output()), 30, interval=0.2, what="the planner's goal")
        goal = (float(goal.group(1)), float(goal.group(2)))
        assert math.dist(goal, person) < 0.5, (goal, person)

        def plan_end():
            got = plans.take()
            return (got[-1].poses[-1].pose.position.x, got[-1].poses[-1].pose.position.y) if got and got[-1].poses else None

        end = wait_until(plan_end, 15, what="a plan")
        assert math.dist(end, goal) < 0.1, (end, goal)
        # 4. the robot drives toward the person
        far = math.dist((start.x, start.y), person)

        def closer():
            msg = odom.latest()  # None when no new message arrived since the last look
            return msg is not None and math.dist((msg.pose.pose.position.x, msg.pose.pose.position.y), person) < far - 1.0

        wait_until(closer, 40, interval=0.2, what="the robot 1 m closer to the person")
        assert not sim_status(system).get("collided", False)
    finally:
        probe.close()
        assert system.stop() == 0
