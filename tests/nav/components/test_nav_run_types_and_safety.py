"""Planner as a Server and an ActionServer, the Controller's ControlPath action, the
MotionServer's recording, and the DriveManager's process wiring (an event action through its
control socket, a restart under its fallback ladder), in real processes. The DriveManager's
hold, emergency stop, unblock maneuvers and settling are tested on robot time in
test_drive_manager_on_robot_time.py; the MapServer's maps and save_map in
test_map_server_on_harness.py."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

HEADER = """
from emos.actors.nav import RobotConfig, RobotType, RobotGeometry, LinearCtrlLimits, AngularCtrlLimits
from emos.actors.nav.components import *
from tests.nav.components.fake_base import FakeBase
robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.15, 0.3]),
                    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                    ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
"""


def _system(tmp_path, body, components):
    return SystemUnderTest(tmp_path, HEADER + body, env={"PYTHONPATH": str(REPO)}).wait_up(timeout=60, components=components)


def test_planner_server_and_controller_control_path_action(tmp_path):
    from emos.actors.nav.components.convert import pose_stamped
    from emos.actors.nav.components.interfaces import (
        ControlPathFeedback,
        ControlPathGoal,
        ControlPathResult,
        PlanPathRequest,
        PlanPathResponse,
    )
    from emos.core.services import ActionClient, ServiceClient
    from tests.nav.components.fake_base import write_room_map

    map_file = write_room_map(tmp_path / "room.yaml")
    system = _system(tmp_path, f"""
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path={map_file!r}))
planner = Planner(component_name="planner", config=PlannerConfig(planner_id="CostToGo"))
planner.run_type = "Server"
controller = Controller(component_name="controller", config=ControllerConfig(algorithm="PurePursuit"))
controller.run_type = "ActionServer"
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.2))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.0))])
launcher.kompass(components=[map_server, planner, controller, driver], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "map_server", "planner", "controller", "driver"])
    plan_srv = ServiceClient("planner/service", PlanPathRequest, PlanPathResponse, ctx=system.ctx, timeout=30)
    follow = ActionClient("controller/action", ControlPathGoal, ControlPathFeedback, ControlPathResult, ctx=system.ctx)
    from emos.transport.pubsub import Subscriber

    odom = Subscriber(system.ctx, "/odom", M.Odometry)
    try:
        bad = plan_srv.call(PlanPathRequest(goal=pose_stamped(3.0, 1.0, 0.0, "map")))
        assert not bad.success and "INVALID_GOAL" in bad.message
        res = plan_srv.call(PlanPathRequest(goal=pose_stamped(2.0, 3.0, 0.0, "map")))
        assert res.success, res.message
        end = res.plan.poses[-1].pose.position
        assert len(res.plan.poses) > 20 and np.hypot(end.x - 2.0, end.y - 3.0) < 1e-6
        feedback: list = []
        result = follow.send_goal(ControlPathGoal(path=res.plan), feedback_callback=feedback.append, timeout=90)
        assert result.success, result.message
        assert feedback and feedback[0].distance_left > feedback[-1].distance_left
        o = wait_until(lambda: next(iter(odom.take()[-1:]), None), 30)
        assert np.hypot(o.pose.pose.position.x - 2.0, o.pose.pose.position.y - 3.0) < 0.3
    finally:
        plan_srv.close()
        odom.close()
        system.stop()


def test_planner_action_drives_to_the_goal_while_the_motion_server_records(tmp_path):
    from emos.actors.nav.components.convert import pose_stamped
    from emos.actors.nav.components.interfaces import (
        MotionRecordingFeedback,
        MotionRecordingGoal,
        MotionRecordingResult,
        PathTrackingError,
        PlanPath,
    )
    from emos.core.services import ActionClient
    from tests.nav.components.fake_base import write_room_map

    map_file = write_room_map(tmp_path / "room.yaml")
    system = _system(tmp_path, f"""
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path={map_file!r}))
planner = Planner(component_name="planner", config=PlannerConfig(planner_id="CostToGo", loop_rate=1.0))
planner.run_type = "ActionServer"
controller = Controller(component_name="controller", config=ControllerConfig(algorithm="PurePursuit"))
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.2))
recorder = MotionServer(component_name="recorder", config=MotionServerConfig(tests_folder={str(tmp_path / 'rec')!r}))
recorder.run_type = "ActionServer"
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.0))])
launcher.kompass(components=[map_server, planner, controller, driver, recorder], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "map_server", "planner", "controller", "driver", "recorder"])
    nav = ActionClient("planner/plan_path", PlanPath.Goal, PlanPath.Feedback, PlanPath.Result, ctx=system.ctx)
    rec = ActionClient("recorder/action", MotionRecordingGoal, MotionRecordingFeedback, MotionRecordingResult, ctx=system.ctx)
    recorded: dict = {}
    try:
        recording = threading.Thread(target=lambda: recorded.setdefault("r", rec.send_goal(
            MotionRecordingGoal(duration=3.0, timestep=0.1, name="drive"), timeout=30)), daemon=True)
        feedback: list = []
        bad = nav.send_goal(PlanPath.Goal(goal=pose_stamped(2.0, 3.2, 0.0, "map").pose,
                                          end_tolerance=PathTrackingError(lateral_distance_error=-0.1)), timeout=30)
        assert not bad.success and "lateral_distance_error" in bad.message, bad.message
        # a goal sent while another runs preempts it
        first: dict = {}
        elsewhere = PlanPath.Goal(goal=pose_stamped(5.0, 1.0, 0.0, "map").pose)  # behind the wall
        runner = threading.Thread(target=lambda: first.setdefault("r", nav.send_goal(elsewhere, timeout=60)), daemon=True)
        runner.start()
        time.sleep(1.0)
        goal = PlanPath.Goal(goal=pose_stamped(2.0, 3.2, 0.0, "map").pose, end_tolerance=PathTrackingError(lateral_distance_error=0.2))
        # Recording starts with the goal it is to record: started with the test, its 3 s could
        # end before the drive on a loaded machine (the rejected goal and the preemption first).
        recording.start()
        result = nav.send_goal(goal, feedback_callback=feedback.append, timeout=90)
        runner.join(10)
        assert first["r"].message == "preempted by a newer goal", first
        assert result.success and result.message == "goal reached", result.message
        assert feedback and feedback[0].plan_length > 0
        recording.join(30)
        r = recorded["r"]
        assert r.success and r.file.endswith(".csv")
        data = np.genfromtxt(r.file, delimiter=",", names=True)
        assert len(data) >= 20 and np.nanmax(np.abs(data["cmd_vx"])) > 0.05  # it recorded the drive
    finally:
        system.stop()


def test_stop_action_holds_the_robot_whatever_the_controller_sends(tmp_path):
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient
    from emos.transport.pubsub import Publisher, Subscriber

    system = _system(tmp_path, """
driver = DriveManager(component_name="driver", config=DriveManagerConfig(stop_hold_time=1.0))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 3.2, 0.0))])
launcher.kompass(components=[driver], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "driver"])
    control = Publisher(system.ctx, "/control", M.Twist, publisher_id="test_controller")
    cmd = Subscriber(system.ctx, "/cmd_vel", M.Twist, queue_size=200)
    client = RpcClient(control_socket(system.ctx, "driver"))
    done = threading.Event()

    def drive() -> None:
        while not done.is_set():
            control.publish(M.Twist(linear=M.Vector3(x=0.2)))
            time.sleep(0.05)

    worker = threading.Thread(target=drive, daemon=True)
    try:
        worker.start()
        wait_until(lambda: any(c.linear.x > 0.15 for c in cmd.take()), 10, what="driving")
        # Through the control socket, as an event's Action reaches it. How long the hold lasts
        # is tested on robot time in test_drive_manager_on_robot_time.py: here the wall clock is
        # the robot's, and a loaded machine stretches every sleep.
        assert client.call("execute_method", method="stop") is True
        cmd.take()
        wait_until(lambda: any(c.linear.x == 0.0 for c in cmd.take()), 10, what="a stop command")
        wait_until(lambda: any(c.linear.x > 0.1 for c in cmd.take()), 30, what="driving again after the hold")
    finally:
        done.set()
        worker.join(2)
        client.close()
        control.close(), cmd.close()
        system.stop()


def test_a_restarted_drive_manager_waits_for_its_first_scan_instead_of_failing(tmp_path):
    """Commands arrive at 20 Hz, scan and odometry at 4 Hz: a fresh DriveManager gets a command
    before its first scan. That holds the robot but is no SYSTEM failure within the inputs'
    timeouts, so ``on_system_fail(restart)`` does not restart it again and again."""
    from emos.transport.pubsub import Publisher, Subscriber

    system = _system(tmp_path, """
from emos import Action
driver = DriveManager(component_name="driver")
driver.on_system_fail(Action(driver.restart))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 3.2, 0.0), rate=4.0)])
launcher.kompass(components=[driver], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "driver"])
    control = Publisher(system.ctx, "/control", M.Twist, publisher_id="test_controller")
    cmd = Subscriber(system.ctx, "/cmd_vel", M.Twist, queue_size=200)
    status = Subscriber(system.ctx, "/driver/status", M.ComponentStatus, queue_size=200)
    done = threading.Event()

    def drive() -> None:
        while not done.is_set():
            control.publish(M.Twist(linear=M.Vector3(x=0.05)))
            time.sleep(0.05)

    worker = threading.Thread(target=drive, daemon=True)
    try:
        worker.start()
        wait_until(lambda: any(c.linear.x > 0.01 for c in cmd.take()), 20, what="driving")
        first = system.pid("driver")
        system.rpc.call("lifecycle", component="driver", request="restart", wait=False)
        second = system.wait_new_pid("driver", first, timeout=30)
        status.take()
        wait_until(lambda: any(c.linear.x > 0.01 for c in cmd.take()), 20, what="driving after the restart")
        time.sleep(1.0)
        assert system.pid("driver") == second  # not restarted again by its on_system_fail ladder
        levels = [s.status for s in status.take()]
        assert HealthLevel.SYSTEM_FAILURE not in levels, levels
        assert "fallback handler=on_system_fail" not in system.output()
    finally:
        done.set()
        worker.join(2)
        control.close(), cmd.close(), status.close()
        system.stop()
