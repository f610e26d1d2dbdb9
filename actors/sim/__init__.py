"""EMOS simulation: a headless pybullet world with robots, sensors, a clock and pictures.

Quick use::

    from emos.actors.sim import World, SimClock, Lidar, Odometry
    world = World.demo_house(clock=SimClock(mode="lockstep"))   # or World.from_barn(1)
    robot = world.add_robot("jackal", pose=(1.0, 1.0, 0.0))
    lidar = world.add_sensor(Lidar(robot))
    robot.command(0.5, 0.0, 0.2)
    world.step(100)
    scan = lidar.latest

Heavy dependencies (pybullet, Pillow, scipy) load on first use; names are resolved lazily so
``import emos.actors.sim`` stays cheap.
"""
from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "World": ".world", "SimClock": ".clock", "ClockMode": ".clock", "SimRate": ".clock",
    "Box": ".primitives", "Cylinder": ".primitives", "Wall": ".primitives",
    "MovingObstacle": ".moving",
    "RobotSpec": ".robots", "DriveType": ".robots", "JACKAL": ".robots", "TURTLEBOT3": ".robots",
    "RACECAR": ".robots", "TURTLEBOT3_WAFFLE_PI": ".robots", "HOLONOMIC": ".robots", "robot_spec": ".robots",
    "SimRobot": ".body", "Contact": ".body",
    "Lidar": ".sensors", "LidarConfig": ".sensors", "ScanReading": ".sensors",
    "Camera": ".sensors", "CameraConfig": ".sensors", "CameraReading": ".sensors",
    "Odometry": ".sensors", "OdometryConfig": ".sensors", "OdometryReading": ".sensors",
    "ContactSensor": ".sensors", "ContactReading": ".sensors",
    "demo_house": ".builders", "from_map": ".builders", "from_barn": ".builders",
    "load_barn_worlds": ".barn_worlds", "BarnWorld": ".barn_worlds",
    "render_topdown": ".render",
    "Simulator": ".component", "SimulatorConfig": ".component",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'emos.actors.sim' has no attribute {name!r}")
    return getattr(importlib.import_module(module, __name__), name)
