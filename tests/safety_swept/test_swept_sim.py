"""The swept-footprint check on the realistic Jackal in a pybullet world: an obstacle beside the
chassis corner, a controller asking for a pure rotation or an arc into it, and no contact,
whatever it asks; a rotation with room still happens.

The DriveManager node runs in ``emos.testing.ComponentHarness`` (its clock is the world's); the
world is the simulator's own: the ``jackal-barn`` robot (official collision shape) on the
calibrated skid-steer drive (yaw gain, lags, friction, 0.25 s watchdog), the Jackal's laser
(720 beams, 270 degrees, noise, mounted 5.5 cm ahead) and wheel + IMU odometry. Commands act
0.1 s after they leave the DriveManager (the compute charge of the BARN runs). Contacts are
pybullet's (``SimRobot.collided``)."""
from __future__ import annotations

import math
from collections import deque

import pytest

from emos import msgs as M
from emos.actors.sim.clock import ClockMode, SimClock
from emos.actors.sim.dynamics import SkidSteerDrive
from emos.actors.sim.jackal import JACKAL_LASER, JACKAL_ODOMETRY
from emos.actors.sim.robots import PRESETS
from emos.actors.sim.sensors.lidar import Lidar
from emos.actors.sim.sensors.wheel_imu import WheelImuOdometry
from emos.actors.sim.world import World
from emos.testing import ComponentHarness
from emos.tools.barn.harness import nav_robot

pytestmark = pytest.mark.sim

SPEC = PRESETS["jackal-barn"]
A, B = SPEC.length / 2, SPEC.width / 2
R = math.hypot(A, B)
DT = 0.01  # s: the world's tick and the harness's
LATENCY = 0.1  # s from /cmd_vel to the base (the BARN runs' compute charge)
CONTROL_PERIOD = 0.1  # s: the controller's rate (10 Hz, as the BARN stack's)
POST_RADIUS = 0.04


def _post_beside_the_front_left_corner() -> tuple[float, float]:
    """A thin post just left of the front-left corner, 1 cm outside the side and inside the
    circle the corners sweep: a left turn of a few degrees swings the side into it."""
    y = B + 0.01 + POST_RADIUS
    return (A - 0.03, y)


class JackalWorld:
    """One world: the robot at the origin facing +x, the post, sensors; ``__call__`` is the
    harness's each_tick: it plays the controller, delivers /cmd_vel after LATENCY, steps the
    world and feeds the DriveManager the scan and odometry."""

    def __init__(self, yaw_gain: float, seed: int = 0) -> None:
        self.world = World(clock=SimClock(dt=DT, mode=ClockMode.LOCKSTEP), seed=seed)
        self.world.add_cylinder(_post_beside_the_front_left_corner(), POST_RADIUS, height=1.0)
        self.robot = self.world.add_robot(SPEC, (0.0, 0.0, 0.0), drive=SkidSteerDrive(yaw_gain=yaw_gain))
        self.lidar = self.world.add_sensor(Lidar(self.robot, JACKAL_LASER))
        self.odom = self.world.add_sensor(WheelImuOdometry(self.robot, JACKAL_ODOMETRY))
        self.control: M.Twist | None = None
        self._pipe: deque[tuple[float, M.Twist]] = deque()
        self._seen = 0
        self._next_control = 0.0
        self.max_yaw = 0.0
        self.min_yaw = 0.0

    def __call__(self, h: ComponentHarness) -> None:
        sent = h.outputs("/cmd_vel")
        for cmd in sent[self._seen:]:
            self._pipe.append((h.time + LATENCY, cmd))
        self._seen = len(sent)
        while self._pipe and self._pipe[0][0] <= h.time + 1e-9:
            _, cmd = self._pipe.popleft()
            self.robot.command(cmd.linear.x, 0.0, cmd.angular.z)
        for sensor, reading in self.world.step():
            if sensor is self.lidar:
                h.feed("/scan", reading.to_msg())
            elif sensor is self.odom:
                h.feed("/odom", reading.to_msg())
        yaw = float(self.robot.pose[2])
        self.max_yaw, self.min_yaw = max(self.max_yaw, yaw), min(self.min_yaw, yaw)
        if self.control is not None and h.time + 1e-9 >= self._next_control:
            h.feed("/control", self.control)
            self._next_control = h.time + CONTROL_PERIOD

    def close(self) -> None:
        self.world.close()


def _drive(v: float, w: float, yaw_gain: float, seconds: float = 2.5, swept: bool = True) -> JackalWorld:
    from emos.actors.nav.components import DriveManager, DriveManagerConfig

    driver = DriveManager(component_name="driver", config=DriveManagerConfig(
        robot=nav_robot(SPEC), critical_zone_distance=0.02, slowdown_zone_distance=0.05, swept_check=swept,
        sensor_pose=(*JACKAL_LASER.mount_xy, 0.0), use_sim_time=True))
    world = JackalWorld(yaw_gain)
    try:
        with ComponentHarness(driver, tick=DT) as h:
            h.advance(0.5, each_tick=world)  # first scans and odometry, standing still
            assert not world.robot.collided
            world.control = M.Twist(linear=M.Vector3(x=v), angular=M.Vector3(z=w))
            h.advance(seconds, each_tick=world)
    except BaseException:
        world.close()
        raise
    return world


@pytest.mark.parametrize("v, w, yaw_gain", [(0.0, 1.0, 1.0), (0.0, 1.0, 0.6), (0.0, 3.0, 1.0), (0.3, 1.5, 1.0),
                                             (0.3, 1.5, 0.6), (0.8, 2.0, 1.0), (-0.3, 1.5, 1.0)],
                         ids=["rotate-1", "rotate-1-slipping", "rotate-3", "arc-slow", "arc-slow-slipping", "arc-fast",
                              "reverse-arc"])
def test_no_contact_whatever_the_controller_asks(v, w, yaw_gain):
    world = _drive(v, w, yaw_gain)
    try:
        assert not world.robot.collided, (world.robot.first_contacts, world.robot.pose)
    finally:
        world.close()


def test_without_the_check_the_same_rotation_touches():
    """The scene is a real hazard: the old DriveManager (zones only) lets the rotation through."""
    world = _drive(0.0, 1.0, 1.0, swept=False)
    try:
        assert world.robot.collided
    finally:
        world.close()


def test_a_rotation_with_room_still_happens():
    """Turning right swings the left side away from the post: the DriveManager lets it through
    and the robot turns by more than a quarter turn in 2 s."""
    world = _drive(0.0, -1.0, 0.8, seconds=2.0)
    try:
        assert not world.robot.collided
        assert world.min_yaw < -math.pi / 4, world.min_yaw
    finally:
        world.close()
