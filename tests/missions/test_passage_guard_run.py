"""The passage guard through real supervised processes (issue 39): the house's point-navigation
stack, the Behaviors with the guard and the give-way on (as the patrol runs them), and the
Simulator with a blind person walking back and forth (0.4 m/s) across the way from the middle
doorway into the right room (x = 6.5, y 0.5 to 3.6). The robot starts in the left room facing
the doorway (4.0, 3.25) and drives back and forth between the rooms, through the doorway and
across the person's walk: the guard learns where the person walks (the band), holds the robot
before it while the person would meet it there, and lets it go when it can be through, until it
has held once and the robot has then crossed the person's walk. The robot must never drive into
the person; the person walking into a robot that stopped in its way is counted and printed
(a give-way's back-out that the swept-footprint layer stopped: the open blind-pedestrian case). Everything is
measured on the Simulator's clock and ground truth (``sim_status``) and the Behaviors' counts
(``stats``); the wall clock only bounds a hang. The recipe runs on the realtime simulator, as
the patrol does: under ``--lockstep`` beside two CPU hogs the guard did worse (2 of 4 runs with
a walk-in, 1 without a hold and crossing in 200 simulated s; 6 of 6 realtime runs beside the
same hogs passed), a difference that issue 39 has yet to explain."""
from __future__ import annotations

import math
import threading
import time

import pytest

from emos.core import control
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]

ROBOT_RADIUS, PERSON_RADIUS = 0.2, 0.22
PERSON_X, PERSON_TOP, PERSON_BOTTOM = 6.5, 3.6, 0.5  # its walk, at 0.4 m/s: a 15.5 s cycle
WAYS = ((7.8, 2.2), (3.6, 2.5))  # the right room, the left room: through the doorway and across the walk
WATCH = 20.0  # simulated s the robot watches the person walk before it sets off (1.3 of its cycles)


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


RECIPE = f"""
import os
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components.behaviors import BehaviorsConfig
from emos.actors.nav.components.keys import TopicsKeys
from emos.actors.nav.missions.passages import PassageGuardConfig
from emos.actors.nav.recovery import GiveWayConfig
from emos.actors.nav.stacks import COMMAND_INPUTS, point_navigation_stack
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person

HOUSE_MAP = os.path.join(os.path.dirname(__import__("emos.actors.sim.data", fromlist=["x"]).__file__), "house.yaml")
robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.2, 0.3]))
odom, scan = Topic(name="/odom", msg_type="Odometry"), Topic(name="/scan", msg_type="LaserScan")
command = Topic(name="/cmd_vel", msg_type="Twist")
person = Person(waypoints=np.array([[{PERSON_X}, {PERSON_BOTTOM}], [{PERSON_X}, {PERSON_TOP}]]), speed=0.4, mode="pingpong")
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=(4.0, 3.25, 0.0), moving_obstacles=[person]))
sim.inputs(command=command)
sim.outputs(odom=odom, scan=scan)
stack = point_navigation_stack(robot, RobotFrames(world="map", odom="map", scan="LDS-01"), HOUSE_MAP, odom=odom,
                               command=command, scan=scan, command_inputs=COMMAND_INPUTS)
behaviors = stack.behaviors(config=BehaviorsConfig(local_mapper=stack.local_mapper.component_name, max_rotational_vel=1.0,
                                                   give_way=GiveWayConfig(enabled=True, speed=0.4),
                                                   passage_guard=PassageGuardConfig(enabled=True)))
behaviors.inputs(plan=stack.planner.get_out_topic(TopicsKeys.GLOBAL_PLAN))
stack.driver.config.mover_prediction_time = 0.6
follower = stack.waypoint_follower()
# A test of the guard, not of the supervisor: a loaded machine that stalls a process for 2 s
# must not get it killed as hung (the restarted waypoint follower loses the mission).
launcher = Launcher(heartbeat_timeout=15.0)
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
stack.launch(launcher)
launcher.add_pkg(components=[behaviors, follower], package_name="mission", multiprocessing=True)
launcher.bringup()
"""


def test_the_robot_waits_before_the_persons_way_and_goes_through_without_contact(tmp_path):
    from emos.actors.nav.components.mission_interfaces import FollowWaypointsFeedback, FollowWaypointsGoal, FollowWaypointsResult
    from emos.core.services import ActionCanceled, ActionClient
    from emos.msgs.geometry import Point, Pose

    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["sim", "behaviors", "waypoints", "planner", "controller"],
                                                       timeout=180)
    sim = control.ControlClient("sim", system.ctx, timeout=10.0)
    behaviors = control.ControlClient("behaviors", system.ctx, timeout=10.0)
    least = math.inf
    contacts: list[dict] = []  # each touch, classified by who closed the gap (as recipes/patrol.py does)
    last: list = []  # the previous sample: (sim_time, robot x, robot y, touching)

    def status() -> dict:
        nonlocal least
        st = wait_until(lambda: sim.execute_method("sim_status"), 60, what="sim_status")
        t, (rx, ry), (px, py) = st["sim_time"], st["pose"][:2], st["movers"][0]["pose"][:2]
        gap = math.hypot(px - rx, py - ry) - ROBOT_RADIUS - PERSON_RADIUS
        least = min(least, gap)
        touching = gap <= 0.005
        if touching and last and not last[3]:
            dt = max(t - last[0], 1e-3)
            toward = ((rx - last[1]) * (px - rx) + (ry - last[2]) * (py - ry)) / dt / max(math.hypot(px - rx, py - ry), 1e-9)
            contacts.append({"sim_time": round(t, 2), "robot_speed_toward": round(toward, 3),
                             "kind": "robot_drove_into" if toward > 0.05 else "walked_into_robot"})
        last[:] = [t, rx, ry, touching]
        return st

    try:
        wait_until(lambda: behaviors.execute_method("stats") is not None, 60, what="the behaviors' stats")
        # The robot first watches the person walk (it sees y 2 to 3.6 of the walk through the
        # doorway) for over a cycle: a guard that never saw the person turn at the end of the walk
        # predicts a person walking up at 3.3 m to walk on away (docs/missions.md, cause (3)).
        t_first = status()["sim_time"]
        while status()["sim_time"] - t_first < WATCH:
            time.sleep(0.05)  # the robot stands 2.5 m from the walk: no need to ask the simulator flat out
        # Then back and forth through the doorway (each way crosses the person's walk) until the
        # guard has held the robot once and the robot has then crossed the person's line; at most
        # 200 simulated s.
        client = ActionClient("waypoints/follow_waypoints", FollowWaypointsGoal, FollowWaypointsFeedback, FollowWaypointsResult,
                              ctx=system.ctx)
        result: list = []
        goal = FollowWaypointsGoal(poses=[Pose(position=Point(x=x, y=y)) for x, y in WAYS], number_of_loops=-1)
        def send() -> None:
            try:
                result.append(client.send_goal(goal, None, timeout=1200, goal_id="through"))
            except ActionCanceled:
                pass  # the test cancels the endless patrol once it has seen what it came for

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        st = status()
        t0, held_at, crossed = st["sim_time"], None, False
        while not crossed:
            assert st["sim_time"] - t0 < 200.0, f"no hold and crossing in 200 simulated s: {st}\n" + system.output()[-3000:]
            assert not result, f"the mission ended: {result}"
            st = status()
            if held_at is None and behaviors.execute_method("stats")["passage_hold"] >= 1:
                held_at = st["pose"][:2]
            crossed = held_at is not None and (st["pose"][0] - PERSON_X) * (held_at[0] - PERSON_X) < 0 and \
                abs(st["pose"][0] - PERSON_X) > ROBOT_RADIUS + PERSON_RADIUS + 0.2
        client.cancel("through")
        sender.join(timeout=60)
        log = system.log_path.read_text(errors="replace")
        # The robot never drives into the person. The person is blind (it walks its line whatever
        # stands there): a robot that was caught in the band and stopped can be walked into, and
        # that is counted, not failed: it is issue 39's open blind-pedestrian case (docs/missions.md).
        print(f"least gap {least:.3f} m; contacts {contacts}")
        assert not [c for c in contacts if c["kind"] == "robot_drove_into"], f"{contacts}\n" + log[-3000:]
        # Held before the person's way: the robot's body short of the person's walk.
        assert abs(held_at[0] - PERSON_X) > ROBOT_RADIUS + PERSON_RADIUS + 0.1, f"held at {held_at}, in the person's way"
        # The hold ends by itself, or a give-way takes over from it (a person closing in on the
        # waiting robot): both are the guard's way; a hold that gave up is not.
        assert "hold_passage started" in log, log[-3000:]
        assert "hold_passage done" in log or "hold_passage preempted by give_way" in log, log[-3000:]
        stats = behaviors.execute_method("stats")
        assert stats["passage_hold"] >= 1 and stats["passage_hold_given_up"] == 0, stats
    finally:
        assert system.stop() == 0
