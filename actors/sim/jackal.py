"""The Jackal's sensing as the BARN simulator has it: the front laser and the state estimate.

- :data:`JACKAL_LASER`: a Hokuyo UST-10 as simulated there: 720 samples over +-2.35619 rad,
  0.1-30 m, 50 Hz, Gaussian range noise (0.01 m), mounted 0.055 m ahead of the centre.
- :data:`JACKAL_ODOMETRY`: wheel odometry fused with an IMU's yaw at 50 Hz
  (:class:`~emos.actors.sim.sensors.wheel_imu.WheelImuOdometry`), never ground truth.
- The body (chassis box + four wheel cylinders) and the drives are the robot presets
  ``jackal-barn`` (skid-steer model) and ``jackal-wheeled`` (pybullet wheels) in robots.py.
"""
from __future__ import annotations

import math

from .sensors.lidar import LidarConfig
from .sensors.wheel_imu import WheelImuOdometryConfig

JACKAL_LASER_HALF_FOV = 2.35619  # rad, the simulated UST-10's angle_max
JACKAL_LASER = LidarConfig(
    fov_deg=math.degrees(2 * JACKAL_LASER_HALF_FOV), beams=720, range_min=0.1, range_max=30.0,
    noise_std=0.01, rate_hz=50.0, mount_xy=(0.055, 0.0), frame_id="front_laser",
)
JACKAL_ODOMETRY = WheelImuOdometryConfig(rate_hz=50.0)
