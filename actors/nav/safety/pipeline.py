"""The DriveManager's command path in one place: safety zones, then limits and smoothing."""
from __future__ import annotations

import numpy as np

from ..controllers.sensors import LaserScan2D
from ..robot import RobotConfig
from .commands import CommandFilter, CommandFilterConfig
from .zones import SafetyZones, SafetyZonesConfig, ZoneCheck

__all__ = ["DriveSafety"]


class DriveSafety:
    """``step(command, obstacles)`` -> the command to send and the zone check behind it.

    Order matters: the zones scale the *requested* command (slowdown), then the filter applies
    velocity limits, separate acceleration/deceleration limits and smoothing. An emergency
    stop bypasses the filter: zero is sent at once and the filter restarts from rest, because
    a deceleration ramp is exactly what must not happen when an obstacle is inside the
    critical zone (the motor controller brakes as hard as it physically can).
    """

    def __init__(self, robot: RobotConfig, zones: SafetyZonesConfig | None = None,
                 commands: CommandFilterConfig | None = None,
                 sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.zones = SafetyZones(robot, zones, sensor_pose)
        self.filter = CommandFilter(robot, commands)

    def step(self, command: np.ndarray, obstacles: LaserScan2D | np.ndarray | None) -> tuple[np.ndarray, ZoneCheck]:
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        if obstacles is None:  # no sensor data: cannot vouch for the way ahead
            check = ZoneCheck(0.0, float("nan"))
        else:
            cmd, check = self.zones.limit(cmd, obstacles)
        if check.emergency_stop:
            self.filter.reset(np.zeros(3))
            return np.zeros(3), check
        return self.filter(cmd), check
