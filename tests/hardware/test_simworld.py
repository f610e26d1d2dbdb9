"""The emulators backed by the pybullet world: the emulated Create 2 moves the pybullet robot by
its wheel speeds (and its bumper feels the pybullet walls); the emulated RPLIDAR ray-casts that
world from the robot's pose. Driven through our serial drivers, as a recipe does."""
from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from emos.actors.hardware.create2 import protocol as P
from emos.actors.hardware.create2.driver import Create2Link
from emos.actors.hardware.create2.odometry import DiffDriveOdometry
from emos.actors.hardware.rplidar.driver import RplidarDriver
from emos.actors.hardware.rplidar.emulator import MapRaycaster
from emos.actors.hardware.simworld import SimulatedDevices
from emos.packages import get_package_share_directory

pytestmark = pytest.mark.sim

MAP = os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_webots.yaml")


@pytest.fixture
def devices(tmp_path):
    dev = SimulatedDevices(MAP, (0.0, 0.0, 0.0), base_link=str(tmp_path / "create2"), lidar_link=str(tmp_path / "rplidar")).start()
    yield dev
    dev.close()


def _ticks(dev, n: int, timeout: float = 60.0) -> None:
    """Wait ``n`` emulator ticks (15 ms of robot time each); ``timeout`` only bounds a hang."""
    end, deadline = dev.base.ticks + n, time.monotonic() + timeout
    while dev.base.ticks < end:
        assert time.monotonic() < deadline, "emulator stalled"
        time.sleep(0.005)


def test_wheel_speeds_move_the_pybullet_robot_and_the_encoders_say_so(devices):
    link = Create2Link(str(devices.base.link))
    link.open()
    try:
        odo = DiffDriveOdometry()
        for right, left, ticks in ((200, 200, 60), (150, -150, 40), (200, 200, 40), (0, 0, 20)):
            link.drive_direct(right, left)
            _ticks(devices, ticks)
        _ticks(devices, 5)
        for frame in link.take_frames():
            odo.update(frame.get(P.PKT_ENCODER_LEFT), frame.get(P.PKT_ENCODER_RIGHT), P.STREAM_PERIOD_S)
        x, y, th = devices.truth()
        assert math.hypot(x, y) > 0.2  # it really drove, in pybullet
        assert abs(odo.x - x) < 0.01 and abs(odo.y - y) < 0.01 and abs(math.remainder(odo.th - th, 2 * math.pi)) < 0.02
        assert not devices.collided and link.parser.dropped_bytes == 0
    finally:
        link.close()


def test_lidar_ray_casts_the_pybullet_world_from_the_robots_pose(devices):
    driver = RplidarDriver(str(devices.lidar.link))
    driver.start()
    try:
        for _ in range(2):  # spin-up, then a whole revolution
            scan = driver.wait_scan(20.0)
        assert scan is not None and len(scan.ranges) == 360
        expected = MapRaycaster(MAP)(devices.truth(), -math.pi + np.arange(360) * 2 * math.pi / 360)
        both = np.isfinite(scan.ranges) & np.isfinite(expected)
        assert both.sum() > 300
        # pybullet's walls are the map's cells extruded: the two casts agree to a cell or so
        assert np.median(np.abs(scan.ranges[both] - expected[both])) < 0.05
        assert devices.rays_cast >= 720 and driver.corrupt_scans == 0
    finally:
        driver.stop()


def test_a_pybullet_wall_presses_the_bumper_and_stops_the_body(devices):
    link = Create2Link(str(devices.base.link))
    link.open()
    try:
        link.drive_direct(300, 300)  # straight ahead until something is in the way
        deadline = time.monotonic() + 60.0
        while not devices.base.bumps:
            assert time.monotonic() < deadline, "never reached a wall"
            time.sleep(0.01)
        where = devices.truth()
        _ticks(devices, 30)  # still commanded forward: the wall holds it
        assert math.dist(devices.truth()[:2], where[:2]) < 0.01
        _ticks(devices, 3)
        frames = link.take_frames()
        assert frames and frames[-1].bumped and frames[-1].get(P.PKT_ENCODER_LEFT) == frames[-2].get(P.PKT_ENCODER_LEFT)
    finally:
        link.close()
