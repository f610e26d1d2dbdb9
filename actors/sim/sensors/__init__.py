"""Simulated sensors: lidar, RGB-D camera, odometry, contacts."""
from .base import Sensor
from .camera import Camera, CameraConfig, CameraReading, depth_to_points
from .contacts import ContactReading, ContactSensor
from .lidar import Lidar, LidarConfig, ScanReading
from .odometry import Odometry, OdometryConfig, OdometryReading

__all__ = [
    "Camera", "CameraConfig", "CameraReading", "ContactReading", "ContactSensor", "Lidar", "LidarConfig",
    "Odometry", "OdometryConfig", "OdometryReading", "ScanReading", "Sensor", "depth_to_points",
]
