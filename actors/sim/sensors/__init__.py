"""Simulated sensors: lidar, RGB-D camera, odometry, contacts."""
from .base import Sensor
from .camera import Camera, CameraConfig, CameraReading, depth_to_points
from .contacts import ContactReading, ContactSensor
from .lidar import Lidar, LidarConfig, ScanReading
from .odometry import Odometry, OdometryConfig, OdometryReading
from .wheel_imu import WheelImuOdometry, WheelImuOdometryConfig

__all__ = [
    "Camera", "CameraConfig", "CameraReading", "ContactReading", "ContactSensor", "Lidar", "LidarConfig",
    "Odometry", "OdometryConfig", "OdometryReading", "ScanReading", "Sensor", "WheelImuOdometry",
    "WheelImuOdometryConfig", "depth_to_points",
]
