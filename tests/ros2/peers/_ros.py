"""What every peer shares: loading ROS 2 the way EMOS does (no LD_LIBRARY_PATH needed), and a QoS
from a name. The peers are plain rclpy programs; they use EMOS only to find the libraries."""
from __future__ import annotations

import importlib
import sys


def rclpy_ready():
    from emos.interop.ros2 import env

    env.ensure_loadable()
    import rclpy

    return rclpy


def msg_class(ros_type: str):
    from emos.interop.ros2 import env

    package, _, name = ros_type.partition("/msg/")
    env.prepare_package(package)
    return getattr(importlib.import_module(f"{package}.msg"), name)


def qos(name: str):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

    if name == "sensor_data":
        return qos_profile_sensor_data
    if name == "latched":
        return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if name == "best_effort":
        return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    return QoSProfile(depth=10)


def say(*parts) -> None:
    print(*parts, flush=True)
    sys.stdout.flush()
