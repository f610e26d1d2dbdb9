"""The BARN Jackal's laser and its wheel + IMU odometry."""
import math

import numpy as np
import pytest

from emos.actors.sim import Lidar, Odometry, OdometryConfig
from emos.actors.sim.jackal import JACKAL_LASER
from emos.actors.sim.sensors import WheelImuOdometry, WheelImuOdometryConfig

pytestmark = pytest.mark.sim


def test_official_laser_geometry():
    assert JACKAL_LASER.beams == 720
    assert JACKAL_LASER.angle_min == pytest.approx(-2.35619, abs=1e-6)
    assert JACKAL_LASER.angle_max == pytest.approx(2.35619, abs=1e-6)
    assert (JACKAL_LASER.range_min, JACKAL_LASER.range_max, JACKAL_LASER.rate_hz) == (0.1, 30.0, 50.0)
    assert JACKAL_LASER.mount_xy == (0.055, 0.0)
    assert JACKAL_LASER.noise_std > 0


def test_laser_is_mounted_ahead_runs_at_50_hz_and_is_noisy(make_world):
    world = make_world()
    world.add_wall((3.0, -2.0), (3.0, 2.0), thickness=0.1)  # face at x = 2.95
    robot = world.add_robot("jackal-barn", (0.0, 0.0, 0.0))
    lidar = world.add_sensor(Lidar(robot, JACKAL_LASER))
    readings = [r for s, r in world.step(100) if s is lidar]  # 1 s
    assert len(readings) == 50
    centre = np.array([r.ranges[359:361].mean() for r in readings])
    # 2.95 m from the robot's centre, 2.895 m from the laser 0.055 m ahead of it.
    assert centre.mean() == pytest.approx(2.895, abs=0.005)
    assert 0.003 < np.std([r.ranges[360] for r in readings]) < 0.03
    assert readings[0].sensor_pose[0] == pytest.approx(0.055)


def _turning_run(make_world, odometry, seconds=10.0):
    world = make_world(ground=False, seed=4)
    robot = world.add_robot("jackal-barn", (0.0, 0.0, 0.0))
    sensor = world.add_sensor(odometry(robot))
    for k in range(int(seconds * 100)):
        robot.command(1.0, 0.0, 1.5 if (k // 200) % 2 == 0 else -1.0)
        world.step()
    return robot, sensor.latest


def test_wheel_imu_odometry_tracks_the_real_turn_where_wheel_odometry_does_not(make_world):
    robot, imu = _turning_run(make_world, lambda r: WheelImuOdometry(r))
    robot2, wheel = _turning_run(make_world, lambda r: Odometry(r, OdometryConfig(noisy=True)))
    assert robot.drive.yaw_gain == robot2.drive.yaw_gain  # same seed, same episode draw

    def yaw_error(reading, truth):
        return abs(math.remainder(reading.yaw - truth.pose[2], 2 * math.pi))

    assert yaw_error(imu, robot) < 0.15
    assert yaw_error(wheel, robot2) > 0.5  # the encoders count the commanded turn (gain < 1)
    assert math.dist((imu.x, imu.y), robot.pose[:2]) < 0.5
    # Never the ground truth.
    assert (imu.x, imu.y, imu.yaw) != tuple(robot.pose)
    assert imu.omega != robot.twist[2]


def test_wheel_imu_odometry_draws_its_errors_per_episode(make_world):
    biases = set()
    for seed in range(5):
        world = make_world(ground=False, seed=seed)
        robot = world.add_robot("jackal-barn", (0.0, 0.0, 0.0))
        odom = world.add_sensor(WheelImuOdometry(robot))
        biases.add((round(odom.gyro_bias, 9), round(odom.wheel_scale, 9)))
    assert len(biases) == 5
    with pytest.raises(ValueError, match="gyro_noise"):
        WheelImuOdometryConfig(gyro_noise=-1.0)


def test_rays_stopped_at_the_world_bounds_read_the_same_as_full_range_rays(make_world):
    """The lidar ends its rays where nothing can be hit any more (World.ray_bounds): the
    readings must be identical to rays cast to the full 30 m."""
    from emos.actors.sim import MovingObstacle, load_barn_worlds
    from emos.actors.sim.builders import barn_shapes
    from emos.actors.sim.primitives import Cylinder
    from emos.actors.sim.sensors import LidarConfig

    config = LidarConfig(fov_deg=360.0, beams=720, range_max=30.0, rate_hz=50.0)  # no noise
    scans = []
    for shortcut in (True, False):
        world = make_world()
        world.add(barn_shapes(load_barn_worlds()[1]))
        world.add(MovingObstacle(Cylinder((0.0, 0.0), 0.3), [(-6.0, 5.0), (3.0, 5.0)], speed=1.0, name="walker"))
        robot = world.add_robot("jackal-barn", (-2.25, 3.0, 1.57))
        other = world.add_robot("jackal", (-7.0, 3.0, 0.0))  # outside the obstacle field
        lidar = world.add_sensor(Lidar(robot, config))
        if not shortcut:
            world.ray_bounds = lambda: None
        else:
            bounds = world.ray_bounds()
            assert bounds[0] < -7.2 and bounds[2] > 2.9  # the other robot and the walker's path count
        world.step(20)
        scans.append(lidar.latest.ranges)
        assert other is not None
    assert np.isfinite(scans[0]).sum() > 300
    assert np.array_equal(np.isfinite(scans[0]), np.isfinite(scans[1]))
    ok = np.isfinite(scans[0])
    assert np.allclose(scans[0][ok], scans[1][ok], atol=1e-4)
