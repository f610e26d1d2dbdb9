"""Planner as a Server and an ActionServer, the Controller's ControlPath action, the
DriveManager's emergency stop and unblock maneuver, the MapServer's PCD maps and save_map."""
from __future__ import annotations

import math
import threading
import time

import numpy as np

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until
import pytest

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
    from emos.actors.nav.components.interfaces import (ControlPathFeedback, ControlPathGoal, ControlPathResult,
                                                        PlanPathRequest, PlanPathResponse)
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
        o = wait_until(lambda: next(iter(odom.take()[-1:]), None), 5)
        assert np.hypot(o.pose.pose.position.x - 2.0, o.pose.pose.position.y - 3.0) < 0.3
    finally:
        plan_srv.close()
        odom.close()
        system.stop()


def test_emergency_stop_overrides_the_command_and_unblock_backs_out(tmp_path):
    from emos.core.services import ServiceClient
    from emos.transport.pubsub import Publisher, Subscriber

    # The robot faces the wall box (x = 2.8) from 0.5 m; a PCD map of two posts on the side.
    pcd = tmp_path / "posts.pcd"
    pts = np.array([[0.0, 0.0, 0.5], [1.0, 0.5, 0.5], [1.0, 0.5, 0.01]], dtype=np.float32)
    pcd.write_bytes(b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n" + pts.tobytes())
    system = _system(tmp_path, f"""
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.1, slowdown_zone_distance=0.25))
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path={str(pcd)!r}, grid_resolution=0.1))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(2.15, 1.0, 0.0))])
launcher.kompass(components=[driver, map_server], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "driver", "map_server"])
    control = Publisher(system.ctx, "/control", M.Twist, publisher_id="test_controller")
    estop = Subscriber(system.ctx, "/emergency_stop", M.Bool, queue_size=50)
    odom = Subscriber(system.ctx, "/odom", M.Odometry)
    status = Subscriber(system.ctx, "/driver/status", M.ComponentStatus, queue_size=100)
    grid = Subscriber(system.ctx, "/map", M.OccupancyGrid, transient_local=True)
    stop = threading.Event()

    def drive() -> None:  # a controller that insists on driving forward
        while not stop.is_set():
            control.publish(M.Twist(linear=M.Vector3(x=0.3)))
            time.sleep(0.1)

    driver_thread = threading.Thread(target=drive, daemon=True)
    try:
        g = wait_until(lambda: next(iter(grid.take()[-1:]), None), 10, what="the PCD map")
        assert g.info.resolution == np.float32(0.1) and int((g.data == 100).sum()) == 2
        driver_thread.start()
        wait_until(lambda: any(m.data for m in estop.take()), 15, what="emergency_stop True")
        wait_until(lambda: any(s.status == HealthLevel.ALGORITHM_FAILURE and "critical zone" in s.message for s in status.take()), 5,
                   what="the emergency stop reported")
        time.sleep(0.5)
        x_stop = wait_until(lambda: next(iter(odom.take()[-1:]), None), 5).pose.pose.position.x
        assert 2.4 < x_stop < 2.8 - 0.15 - 0.02  # stopped short of the wall (footprint 0.15 m)
        stop.set()
        driver_thread.join(2)
        unblock = ServiceClient("driver/move_to_unblock", M.TriggerRequest, M.TriggerResponse, ctx=system.ctx)
        try:
            res = unblock.call(M.TriggerRequest())
        finally:
            unblock.close()
        assert res.success and "move_backward" in res.message, res.message
        time.sleep(2.0)
        x_after = wait_until(lambda: next(iter(odom.take()[-1:]), None), 5).pose.pose.position.x
        assert x_after < x_stop - 0.1  # it backed away from the wall
    finally:
        stop.set()
        for s in (control, estop, odom, status, grid):
            s.close()
        system.stop()


def test_backing_up_remembers_the_wall_the_laser_no_longer_sees(tmp_path):
    """A 270 degree laser is blind behind. The robot faces the room's west wall (x = 0) from
    0.9 m, turns round, and is asked to back up 1 m: the wall, seen before the turn, must
    shorten the back-out (without the memory it would drive into it)."""
    from emos.core.services import ServiceClient
    from emos.transport.pubsub import Publisher, Subscriber

    system = _system(tmp_path, """
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.1,
                                                                         max_distance=1.0))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(0.9, 2.0, 3.14159), fov_deg=270.0)])
launcher.kompass(components=[driver], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "driver"])
    control = Publisher(system.ctx, "/control", M.Twist, publisher_id="test_controller")
    odom = Subscriber(system.ctx, "/odom", M.Odometry)
    back = ServiceClient("driver/move_backward", M.TriggerRequest, M.TriggerResponse, ctx=system.ctx)

    def latest() -> M.Odometry:
        return wait_until(lambda: next(iter(odom.take()[-1:]), None), 5)

    try:
        time.sleep(1.0)  # the wall ahead is in view, and remembered
        end = time.monotonic() + 30
        while time.monotonic() < end and abs(latest().pose.pose.orientation.yaw()) > 0.1:  # turn to face east
            control.publish(M.Twist(angular=M.Vector3(z=1.0)))
            time.sleep(0.05)
        control.publish(M.Twist())
        time.sleep(1.0)  # the controller's command goes stale: the driver stops
        res = back.call(M.TriggerRequest())
        assert res.success and "shortened" in res.message, res.message
        time.sleep(4.0)
        x = latest().pose.pose.position.x
        assert 0.15 < x < 0.5, x  # backed up towards the wall, and stopped short of it (radius 0.15 m)
    finally:
        back.close()
        control.close()
        odom.close()
        system.stop()


def test_a_back_out_asked_while_the_robot_turns_stops_it_and_is_planned_again_at_rest(tmp_path):
    """A stuck recovery can ask for a back-out while the controller's last command still turns
    the robot: the plan was checked on a scan taken before the turn went on. The DriveManager
    stops the base first and plans the back-out again on a scan taken at rest; the back-out is
    then straight (BARN world 242: a back-out started mid-turn swung the rear into a post)."""
    from emos.core.services import ServiceClient
    from emos.transport.pubsub import Publisher, Subscriber

    system = _system(tmp_path, """
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.1,
                                                                         max_distance=0.5, cmd_timeout=1.0))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(2.0, 2.0, 0.0))])
launcher.kompass(components=[driver], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
""", ["base", "driver"])
    control = Publisher(system.ctx, "/control", M.Twist, publisher_id="test_controller")
    odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=1000)
    cmd = Subscriber(system.ctx, "/cmd_vel", M.Twist, queue_size=1000)
    back = ServiceClient("driver/move_backward", M.TriggerRequest, M.TriggerResponse, ctx=system.ctx)
    stop = threading.Event()

    def turn() -> None:  # the controller keeps turning the robot in place
        while not stop.is_set():
            control.publish(M.Twist(angular=M.Vector3(z=1.0)))
            time.sleep(0.05)

    turner = threading.Thread(target=turn, daemon=True)
    try:
        wait_until(lambda: odom.take(), 10, what="odometry")
        turner.start()
        wait_until(lambda: any(abs(m.twist.twist.angular.z) > 0.5 for m in odom.take()), 10, what="the robot turning")
        cmd.take()
        res = back.call(M.TriggerRequest())
        stop.set()
        assert res.success and "move_backward" in res.message, res.message
        sent: list[tuple[float, float]] = []  # every command the driver sends (the ring keeps only the last few)
        end = time.monotonic() + 2.5
        while time.monotonic() < end:
            sent += [(m.linear.x, m.angular.z) for m in cmd.take()]
            time.sleep(0.01)
        first_back = next(i for i, (vx, _) in enumerate(sent) if vx < -1e-3)
        assert first_back >= 1 and sent[first_back - 1] == (0.0, 0.0), sent[:first_back + 1]  # stopped before backing
        assert all(abs(w) < 1e-9 for vx, w in sent[first_back:] if vx < -1e-3)  # straight back, no turn
        x = wait_until(lambda: next(iter(odom.take()[-1:]), None), 5).pose.pose.position
        assert math.hypot(x.x - 2.0, x.y - 2.0) > 0.3  # it did back out
    finally:
        stop.set()
        turner.join(2) if turner.is_alive() else None
        back.close()
        control.close()
        odom.close()
        cmd.close()
        system.stop()


def test_map_server_save_map_service_round_trips(tmp_path):
    from emos.actors.nav.components.interfaces import SaveMapRequest, SaveMapResponse
    from emos.actors.nav.maps import load_map
    from emos.core.services import ServiceClient
    from tests.nav.components.fake_base import write_room_map

    map_file = write_room_map(tmp_path / "room.yaml")
    system = _system(tmp_path, f"""
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path={map_file!r}))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[map_server], multiprocessing=True)
launcher.bringup()
""", ["map_server"])
    save = ServiceClient("map_server/save_map", SaveMapRequest, SaveMapResponse, ctx=system.ctx)
    try:
        bad = save.call(SaveMapRequest(file_location=str(tmp_path), file_name="../escape"))
        assert not bad.success
        res = save.call(SaveMapRequest(file_location=str(tmp_path / "saved"), file_name="copy"))
        assert res.success, res.message
        assert np.array_equal(load_map(res.path).data, load_map(map_file).data)
    finally:
        save.close()
        system.stop()


def test_planner_action_drives_to_the_goal_while_the_motion_server_records(tmp_path):
    from emos.actors.nav.components.convert import pose_stamped
    from emos.actors.nav.components.interfaces import (MotionRecordingFeedback, MotionRecordingGoal, MotionRecordingResult,
                                                        PathTrackingError, PlanPath)
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
        # is tested on robot time in tests/testing/test_harness.py: here the wall clock is the
        # robot's, and a loaded machine stretches every sleep.
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
