"""The DriveManager's hold, emergency stop, unblock maneuvers and their settling, on robot time.

Each test runs the real DriveManager node in ``emos.testing.ComponentHarness``: the harness's
clock is the robot's, and a kinematic base (the same room and laser as ``FakeBase``) answers
every tick's command with odometry and a scan. What takes seconds of robot time takes no wall
time, and a loaded machine cannot stretch it. The process wiring (the control socket, the
supervisor's restart ladder) is tested in test_nav_run_types_and_safety.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos import msgs as M
from emos.testing import ComponentHarness
from tests.nav.components.fake_base import BOXES, CommandFollower, base_messages

pytestmark = pytest.mark.unit


def _robot():
    from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType

    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.15, 0.3]),
                       ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                       ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))


def _driver(**config):
    from emos.actors.nav.components import DriveManager, DriveManagerConfig

    return DriveManager(component_name="driver", config=DriveManagerConfig(robot=_robot(), **config))


class RoomBase(CommandFollower):
    """FakeBase's kinematics in lockstep with the harness: before every tick it drives the pose
    by the newest command the DriveManager sent, for one tick, and feeds odometry and a scan of
    the room and its ``boxes`` (``fov_deg`` centred ahead). ``control``: the twist a controller
    sends every tick, None while it is silent."""

    def __init__(self, start, fov_deg: float = 360.0):
        super().__init__(start)
        self.fov = math.radians(fov_deg)
        self.boxes = list(BOXES)
        self.control: M.Twist | None = None

    def __call__(self, h: ComponentHarness) -> None:
        v, w = self.move(h)
        odom, scan = base_messages(self.pose, v, w, self.fov, self.boxes)
        h.feed("/odom", odom)
        h.feed("/scan", scan)
        if self.control is not None:
            h.feed("/control", self.control)

    @property
    def yaw(self) -> float:
        return math.atan2(math.sin(self.pose[2]), math.cos(self.pose[2]))


def _trigger(h: ComponentHarness, service: str) -> M.TriggerResponse:
    return h.call(f"driver/{service}", M.TriggerRequest())


def test_stop_holds_the_robot_for_stop_hold_time_whatever_the_controller_sends():
    driver = _driver(stop_hold_time=1.0, loop_rate=20.0)
    base = RoomBase(start=(1.0, 3.2, 0.0))
    base.control = M.Twist(linear=M.Vector3(x=0.2))
    with ComponentHarness(driver, start_time=10.0) as h:
        h.advance(1.0, each_tick=base)
        assert max(c.linear.x for c in h.outputs("/cmd_vel")) > 0.15  # it drives
        assert driver.stop() is True
        h.advance(0.95, each_tick=base)
        held = h.outputs("/cmd_vel")
        assert len(held) >= 19 and all(c.linear.x == 0.0 for c in held)  # commands kept coming at 20 Hz, the robot stood
        h.advance(0.5, each_tick=base)
        assert max(c.linear.x for c in h.outputs("/cmd_vel")) > 0.1  # driving again once the hold of 1.0 robot-seconds is over


def test_emergency_stop_overrides_the_command_and_unblock_backs_out():
    """The robot drives east at the 0.3 m/s a controller insists on, and an obstacle appears
    inside the critical zone ahead (in the slowdown zone the robot would only slow down, in
    lockstep never reaching the critical zone): it stops short of it at once, reports the
    emergency stop, stays stopped, and ``move_to_unblock`` backs it out."""
    driver = _driver(critical_zone_distance=0.1, slowdown_zone_distance=0.25)
    base = RoomBase(start=(1.0, 1.0, 0.0))
    base.control = M.Twist(linear=M.Vector3(x=0.3))
    with ComponentHarness(driver) as h:
        h.advance(1.0, each_tick=base)
        assert h.latest("/cmd_vel").linear.x > 0.25 and h.since("/emergency_stop", 0)[-1].data is False
        front = base.pose[0] + 0.15 + 0.08  # 8 cm beyond the footprint (radius 0.15 m)
        base.boxes.append((front, 0.7, front + 0.2, 1.3))
        h.advance(0.5, each_tick=base)
        assert any(m.data for m in h.outputs("/emergency_stop"))
        assert h.health.is_algorithm_fail and "critical zone" in h.health.to_msg().message
        x_stop = base.pose[0]
        assert x_stop < front - 0.15 - 0.02  # stopped short of the obstacle
        h.advance(1.0, each_tick=base)
        assert base.pose[0] == pytest.approx(x_stop)  # and stays there while the controller insists
        base.control = None
        res = _trigger(h, "move_to_unblock")
        assert res.success and "move_backward" in res.message, res.message
        h.advance(2.0, each_tick=base)
        assert base.pose[0] < x_stop - 0.1  # it backed away from the obstacle


def test_backing_up_remembers_the_wall_the_laser_no_longer_sees():
    """A 270 degree laser is blind behind. The robot faces the room's west wall (x = 0) from
    0.9 m, turns round, and is asked to back up 1 m: the wall, seen before the turn, must
    shorten the back-out (without the memory it would drive into it)."""
    driver = _driver(critical_zone_distance=0.05, slowdown_zone_distance=0.1, max_distance=1.0)
    base = RoomBase(start=(0.9, 2.0, math.pi), fov_deg=270.0)
    with ComponentHarness(driver) as h:
        h.advance(1.0, each_tick=base)  # the wall ahead is in view
        base.control = M.Twist(angular=M.Vector3(z=1.0))
        turned = 0.0
        while abs(base.yaw) > 0.1:  # turn to face east
            assert turned < 10.0, f"still not facing east after {turned:.1f} s of robot time (yaw {base.yaw:.2f})"
            h.advance(h.tick, each_tick=base)
            turned += h.tick
        base.control = M.Twist()
        h.advance(h.tick, each_tick=base)
        base.control = None
        h.advance(1.0, each_tick=base)  # the controller's command goes stale: the driver stops
        assert h.latest("/cmd_vel").linear.x == 0.0 and h.latest("/cmd_vel").angular.z == 0.0
        res = _trigger(h, "move_backward")
        assert res.success and "shortened" in res.message, res.message
        h.advance(4.0, each_tick=base)
        assert 0.15 < base.pose[0] < 0.5, base.pose  # backed up towards the wall, and stopped short of it (radius 0.15 m)


def test_a_back_out_asked_while_the_robot_turns_stops_it_and_is_planned_again_at_rest():
    """A stuck recovery can ask for a back-out while the controller's last command still turns
    the robot: the plan was checked on a scan taken before the turn went on. The DriveManager
    stops the base first and plans the back-out again on a scan taken at rest; the back-out is
    then straight (BARN world 242: a back-out started mid-turn swung the rear into a post)."""
    driver = _driver(critical_zone_distance=0.05, slowdown_zone_distance=0.1, max_distance=0.5, cmd_timeout=1.0)
    base = RoomBase(start=(2.0, 2.0, 0.0))
    base.control = M.Twist(angular=M.Vector3(z=1.0))  # the controller keeps turning the robot in place
    with ComponentHarness(driver) as h:
        h.advance(1.0, each_tick=base)
        assert abs(h.latest("/cmd_vel").angular.z) > 0.5  # turning
        mark = h.mark()
        res = _trigger(h, "move_backward")
        assert res.success and "move_backward" in res.message, res.message
        h.advance(0.5, each_tick=base)  # the controller's turn commands still arrive a while
        base.control = None
        h.advance(2.0, each_tick=base)
        sent = [(m.linear.x, m.angular.z) for m in h.since("/cmd_vel", mark)]  # every command since the call
        first_back = next(i for i, (vx, _) in enumerate(sent) if vx < -1e-3)
        assert sent[0] == (0.0, 0.0) and sent[first_back - 1] == (0.0, 0.0), sent[:first_back + 1]  # stopped before backing
        assert all(abs(w) < 1e-9 for vx, w in sent[first_back:] if vx < -1e-3)  # straight back, no turn
        assert math.hypot(base.pose[0] - 2.0, base.pose[1] - 2.0) > 0.3  # it did back out


def test_a_fresh_drive_manager_holds_without_failing_until_its_first_scan_is_overdue():
    """A command before the first scan holds the robot; it becomes a SYSTEM failure naming the
    scan only once ``sensor_timeout`` has passed since activation (robot seconds)."""
    driver = _driver(sensor_timeout=0.5, odom_timeout=0.5)
    with ComponentHarness(driver) as h:
        h.play("/control", [M.Twist(linear=M.Vector3(x=0.2))] * 8)  # 0.4 s of commands, no scan, no odometry
        assert all(c.linear.x == 0.0 for c in h.outputs("/cmd_vel"))
        assert not h.health.is_system_fail
        h.play("/control", [M.Twist(linear=M.Vector3(x=0.2))] * 4)
        assert h.health.is_system_fail and "no odometry yet" in h.health.to_msg().message


@pytest.mark.parametrize("last_word", ["drive", "stand still"])
def test_a_silent_command_source_stops_the_robot_and_is_a_fault_unless_it_last_said_stand_still(last_word):
    """A controller that goes quiet mid-drive (its last command says drive) is a fault: the robot
    stops and the input is reported. One whose last command was zero (a controller or a motion
    test that finished) left the robot standing still on purpose: no fault, no stream of errors."""
    driver = _driver(cmd_timeout=0.5, loop_rate=20.0)
    base = RoomBase(start=(1.0, 3.2, 0.0))
    base.control = M.Twist(linear=M.Vector3(x=0.2))
    with ComponentHarness(driver) as h:
        h.advance(1.0, each_tick=base)
        assert max(c.linear.x for c in h.outputs("/cmd_vel")) > 0.15
        if last_word == "stand still":
            base.control = M.Twist()
            h.advance(0.5, each_tick=base)
        base.control = None  # the source goes quiet
        h.advance(2.0, each_tick=base)
        assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in h.outputs("/cmd_vel")[-10:])
        if last_word == "drive":
            assert not h.health.is_healthy and "no command for" in h.health.to_msg().message
        else:
            assert h.health.is_healthy, h.health.to_msg().message
