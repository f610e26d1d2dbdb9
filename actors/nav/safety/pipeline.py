"""The DriveManager's command path in one place: safety zones, then limits and smoothing, then
the swept-footprint check of what is about to be sent."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..controllers.sensors import LaserScan2D
from ..robot import RobotConfig
from .commands import CommandFilter, CommandFilterConfig
from .swept import FREE, ScanCache, SweptCheck, SweptConfig, SweptFootprint, SweptPoints
from .zones import SafetyZones, SafetyZonesConfig, ZoneCheck

__all__ = ["DriveSafety"]


class DriveSafety:
    """``step(command, obstacles)`` -> the command to send and the zone check behind it.

    Order matters: the zones scale the *requested* command (slowdown), then the filter applies
    velocity limits, separate acceleration/deceleration limits and smoothing. An emergency
    stop bypasses the filter: zero is sent at once and the filter restarts from rest, because
    a deceleration ramp is exactly what must not happen when an obstacle is inside the
    critical zone (the motor controller brakes as hard as it physically can).

    Last, with ``swept`` set, the swept-footprint check (:mod:`.swept`) looks at the command the
    filter produced, rotations included: it passes, is slowed along the same path, or becomes a
    stop (zero at once, as an emergency stop). ``last_swept`` keeps its verdict.
    """

    def __init__(self, robot: RobotConfig, zones: SafetyZonesConfig | None = None,
                 commands: CommandFilterConfig | None = None,
                 sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 swept: SweptConfig | None = None) -> None:
        self.zones = SafetyZones(robot, zones, sensor_pose)
        self.filter = CommandFilter(robot, commands)
        self.swept = SweptFootprint(robot, swept) if swept is not None else None
        self.last_swept: SweptCheck = FREE
        self._scan_points = ScanCache()

    def swept_points(self, scan: object, extra: object, build: Callable[[], np.ndarray]) -> SweptPoints | None:
        """The swept check's obstacle points for one scan (``scan``: its message, compared by
        identity; ``extra``: anything else they depend on, e.g. whether the pose was known),
        prepared once: ``build()`` (the points in the robot frame, (N, 2)) runs only when a new
        scan (or ``extra``) comes, and every command until then reuses what it made. None when
        the check is off."""
        swept = self.swept
        if swept is None:
            return None
        return self._scan_points.get(scan, extra, lambda: swept.prepare(build()))

    def step(self, command: np.ndarray, obstacles: LaserScan2D | np.ndarray | None,
             swept_points: np.ndarray | SweptPoints | None = None, previous: np.ndarray | None = None,
             lead: float = 0.0, history: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, ZoneCheck]:
        """``swept_points`` (N, 2): obstacle points in the robot frame of the pose they were seen
        from, ``lead`` s ago (or :meth:`swept_points`' prepared form of them); ``previous``: the command sent last (default: the filter's last
        output); ``history``: the commands sent recently (see ``SweptFootprint.check``)."""
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        before = self.filter.last.copy() if previous is None else np.asarray(previous, dtype=np.float64).reshape(3)
        self.last_swept = FREE
        if obstacles is None:  # no sensor data: cannot vouch for the way ahead
            check = ZoneCheck(0.0, float("nan"))
        else:
            cmd, check = self.zones.limit(cmd, obstacles)
        if check.emergency_stop:
            self.filter.reset(np.zeros(3))
            return np.zeros(3), check
        out = self.filter(cmd)
        if self.swept is None or swept_points is None:
            return out, check
        out, swept = self.limit_swept(out, before, swept_points, lead, history)
        if swept.stopped:
            return out, ZoneCheck(0.0, swept.clearance)
        return out, check

    def limit_swept(self, command: np.ndarray, previous: np.ndarray, points: np.ndarray | SweptPoints,
                    lead: float = 0.0, history: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, SweptCheck]:
        """The swept-footprint check alone (the unblock maneuvers' commands go through it too)."""
        if self.swept is None:
            return np.asarray(command, dtype=np.float64).reshape(3), FREE
        swept = self.swept.check(command, previous, points, lead, history)
        self.last_swept = swept
        out = np.asarray(command, dtype=np.float64).reshape(3) * swept.scale
        if swept.scale < 1.0:
            # Slower (or stopped) than the filter's ramp: the base brakes as hard as it can, and
            # the filter goes on from what was really sent.
            self.filter.reset(out)
        return out, swept
