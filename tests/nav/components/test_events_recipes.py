"""End to end: the "Events & Resilience" recipes that act on the navigation stack
(recipes/events_and_resilience/{cross_component_events,external_reflexes,context_aware_actions}.py)
run with the real Simulator, Planner, Controller, LocalMapper, DriveManager and Vision processes.

Each test checks that the events fired as often as the recipe says (the Monitor's own counts),
that each action ran in the component it names (its log line), and that the simulated robot did
what the action asked (its true odometry). Generous timeouts; no timing asserts."""
from __future__ import annotations

import math
import re
import time

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest

pytestmark = [pytest.mark.sim, pytest.mark.process]

RECIPES = REPO / "recipes" / "events_and_resilience"


def _constant(source: str, name: str):
    return eval(re.search(rf"^{name} = (.*?)(  #.*)?$", source, re.M).group(1))


def _monitor_fire_counts(system: SystemUnderTest) -> list[int]:
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient

    client = RpcClient(control_socket(system.ctx, "emos_monitor"))
    try:
        return client.call("execute_method", method="monitor_stats", timeout=5.0)["fire_counts"]
    finally:
        client.close()


class _Run:
    """The recipe's system, its log, and the robot's true odometry (x, y, speed) as it goes."""

    def __init__(self, tmp_path, recipe: str, odom_topic: str):
        from emos.transport.pubsub import Subscriber

        self.source = (RECIPES / recipe).read_text()
        self.system = SystemUnderTest(tmp_path, self.source, env={"PYTHONPATH": str(REPO)})
        self.system.wait_up(timeout=90)
        self.odom = Subscriber(self.system.ctx, odom_topic, M.Odometry, queue_size=1000)
        self.poses: list[tuple[float, float, float]] = []  # x, y, forward speed
        self.stamped: list[tuple[float, float, float, float]] = []  # simulated time, x, y, yaw

    def poll(self) -> str:
        for o in self.odom.take():
            p, q = o.pose.pose.position, o.pose.pose.orientation
            self.poses.append((p.x, p.y, o.twist.twist.linear.x))
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            self.stamped.append((o.header.stamp.sec + o.header.stamp.nanosec * 1e-9, p.x, p.y, yaw))
        return self.system.output()

    def wait_for(self, done, timeout: float, what: str) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            out = self.poll()
            if done(out):
                return out
            time.sleep(0.25)
        raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}; robot at "
                             f"{self.poses[-1] if self.poses else None}\n{self.system.output()[-5000:]}")

    def close(self) -> None:
        self.odom.close()
        self.system.stop()


def _after(out: str, first: str, then: str) -> bool:
    i = out.find(first)
    return i >= 0 and out.find(then, i) >= 0


def test_cross_component_events_unblock_direct_sensor_and_clicked_goal(tmp_path):
    run = _Run(tmp_path, "cross_component_events.py", "/odometry/filtered")
    try:
        spawn, goal = _constant(run.source, "ROBOT_SPAWN"), _constant(run.source, "GOAL")
        out = run.wait_for(lambda o: "maneuver move_to_unblock" in o and "parameters set: use_direct_sensor=True" in o,
                           timeout=75, what="the unblock maneuver and the switch to direct sensor mode")
        # C: the click became a PlanPath goal of the real Planner (ActionServer), and the robot drove.
        assert "Got new goal point" in out
        assert f"[planner] planner/plan_path: goal ({goal[0]:.2f}, {goal[1]:.2f}), arrival within 0.05 m" in out, out[-4000:]
        # A: the Controller's stall (ALGORITHM_FAILURE) made the DriveManager run its maneuver (the
        # Controller logs the failure before it publishes it) ...
        assert _after(out, "[controller] DWA: no progress", "[drive_manager] maneuver move_to_unblock"), out[-4000:]
        # B: the mapper's dead scanner (SYSTEM failure) switched the Controller to the raw scan.
        assert "[scan_driver] scan driver crashed" in out and "[mapper] /mapper/scan is stale" in out, out[-4000:]
        # ... and the maneuver moved the robot, which stood still (stalled) in front of the wall.
        def moved_after_stall(_out: str) -> bool:
            xy = [(x, y) for x, y, _ in run.poses]
            stalled = next((i for i in range(25, len(xy)) if xy[i][0] - spawn[0] > 0.2  # it drove towards the goal,
                            and all(abs(v) < 0.01 for _, _, v in run.poses[i - 25:i])), None)  # then stood still 0.5 s
            return stalled is not None and max(math.dist(xy[stalled], p) for p in xy[stalled:]) > 0.08

        run.wait_for(moved_after_stall, timeout=20, what="the robot to drive towards the goal, stall, and move again")
        # keep_event_delay=60 and handle_once: one firing each although both failures persist
        time.sleep(3.0)
        assert _monitor_fire_counts(run.system) == [1, 1, 1]
    finally:
        run.close()


def test_external_reflexes_person_switches_the_controller_to_following(tmp_path):
    import numpy as np

    from emos.actors.sim.person import Person
    from emos.transport.pubsub import Subscriber

    run = _Run(tmp_path, "external_reflexes.py", "/odom")
    detections = Subscriber(run.system.ctx, "/detections", M.Detections, queue_size=200)
    try:
        spawn = _constant(run.source, "ROBOT_SPAWN")
        path, speed = np.array(_constant(run.source, "PERSON_PATH")), float(_constant(run.source, "PERSON_SPEED"))
        person = Person(waypoints=path, speed=speed, mode="once")
        seen: list[float] = []  # simulated times of the frames in which the detector found the person

        def aligned(_out: str) -> tuple | None:
            """A moment after the first detection when the robot had the person dead ahead (< 0.1 rad)
            although, standing where it started, it would have had them >= 0.3 rad off."""
            seen.extend(d.header.stamp.sec + d.header.stamp.nanosec * 1e-9 for d in detections.take() if "person" in list(d.labels))
            for t, x, y, yaw in run.stamped:
                if seen and t > seen[0]:
                    px, py, _ = person.pose_at(t)
                    error = abs(math.remainder(math.atan2(py - y, px - x) - yaw, math.tau))
                    unmoved = abs(math.remainder(math.atan2(py - spawn[1], px - spawn[0]) - spawn[2], math.tau))
                    if error < 0.1 and unmoved >= 0.3:
                        return t, x, y, yaw, error, unmoved
            return None

        out = run.wait_for(lambda o: "track_vision_target: following 'person' with VisionRGBDFollower" in o,
                           timeout=60, what="the reflex (Vision -> event -> Controller)")
        # in this order: the parameter, then the goal, which the follower the parameter selected serves
        assert _after(out, "[controller] parameters set: algorithm='VisionRGBDFollower'",
                      "[controller] track_vision_target: following 'person' with VisionRGBDFollower"), out[-4000:]
        assert "following 'person' with VisionRGBFollower" not in out and "following 'person' with DWA" not in out
        assert _monitor_fire_counts(run.system)[0] >= 1
        arrival = float(np.sum(np.hypot(*np.diff(path, axis=0).T))) / speed  # simulated s until the person stops
        run.wait_for(lambda o: aligned(o) or (run.stamped and run.stamped[-1][0] > arrival + 3.0), timeout=60,
                     what="the robot to turn to the person, or the end of the person's walk")
        found = aligned("")
        assert seen, "the detector never found the person"
        before = [(x, y) for t, x, y, _ in run.stamped if t < seen[0]]
        assert before and max(math.dist(p, spawn[:2]) for p in before) < 0.02  # idle until the person appeared
        assert found is not None, f"the robot never turned to the person\n{run.system.output()[-3000:]}"
        print("aligned at t={:.1f}: robot ({:.2f}, {:.2f}, yaw {:.2f}), bearing error {:.2f} (unmoved: {:.2f})".format(*found))
    finally:
        detections.close()
        run.close()


def test_context_aware_actions_location_name_drives_the_robot(tmp_path):
    run = _Run(tmp_path, "context_aware_actions.py", "/odometry/filtered")
    try:
        spawn = _constant(run.source, "ROBOT_SPAWN")
        kitchen = tuple(float(v) for v in re.search(r'"kitchen": \{"x": ([-0-9.]+), "y": ([-0-9.]+)\}', run.source).groups())
        out = run.wait_for(lambda o: "[operator] the planner reports arrival" in o, timeout=75,
                           what="the robot to reach the kitchen")
        # the names were read from the topic when the event fired: each command its own lookup
        # (lines of different processes: their order in the log is not asserted)
        assert "[operator] says 'garage'" in out and "[operator] says 'kitchen'" in out
        assert out.count("Unknown location: garage") == 1 and out.count(f"Going to kitchen at {kitchen}") == 1, out[-4000:]
        assert "Going to garage" not in out
        assert _monitor_fire_counts(run.system) == [2]  # one firing per command, none on the mapper's status
        run.poll()
        x, y, _ = run.poses[-1]
        assert math.dist((x, y), kitchen) < 0.3, (x, y)  # the Planner got the goal and the robot drove there
        assert math.dist(spawn[:2], kitchen) > 1.5
    finally:
        run.close()


def test_action_arguments_bound_to_list_items_resolve_when_the_event_fires():
    """The page's prompt snippet: ``args=(detections.msg.labels[0],)`` is the first label of the
    message that is there when the action runs (None while there is none)."""
    import numpy as np

    from emos import Action, Topic
    from emos.events.runner import prepare

    detections = Topic(name="/detections", msg_type="Detections")
    prompts = Action(method=lambda label: f"A {label} has been detected.", args=(detections.msg.labels[0],))
    msg = M.Detections(labels=["chair", "person"], scores=np.ones(2), boxes=np.zeros((2, 4)))
    assert prepare(prompts, {"/detections": msg}.get)[0] == ("chair",)
    assert prepare(prompts, {}.get)[0] == (None,)


def test_send_component_action_server_goal_picks_the_server_of_the_goal_type():
    import pytest

    from emos import Topic
    from emos.actions import send_component_action_server_goal
    from emos.actors.nav.components import Controller, Planner
    from emos.actors.nav.components.interfaces import ControlPathGoal, PlanPath, TrackVisionTarget

    controller = Controller(component_name="controller")
    # no vision input: no track_vision_target server, so the goal has nowhere to go
    with pytest.raises(TypeError, match=r"ControlPathGoal \(controller/action\).*got TrackVisionTargetGoal"):
        send_component_action_server_goal(component=controller, request_msg=TrackVisionTarget.Goal(label="person"))
    controller.inputs(vision_detections=Topic(name="detections", msg_type="Detections"))
    track = send_component_action_server_goal(component=controller, request_msg=TrackVisionTarget.Goal(label="person"))
    assert track.kwargs["server_name"] == "controller/track_vision_target"
    follow = send_component_action_server_goal(component=controller, request_msg=ControlPathGoal())
    assert follow.kwargs["server_name"] == "controller/action"
    plan = send_component_action_server_goal(component=Planner(component_name="planner"), request_msg=PlanPath.Goal())
    assert plan.kwargs["server_name"] == "planner/plan_path"
