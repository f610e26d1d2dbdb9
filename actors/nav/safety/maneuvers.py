"""Recovery maneuvers with free-space checks: move_forward, move_backward, rotate_in_place,
move_to_unblock. Each returns a :class:`Maneuver`: the command sequence to play, or why not."""
from __future__ import annotations

import math

import attrs
import numpy as np

from ..controllers.sensors import LaserScan2D, obstacle_points
from ..robot import RobotConfig, RobotGeometry

__all__ = ["Maneuver", "free_travel", "rotation_is_free", "move_forward", "move_backward",
           "rotate_in_place", "move_to_unblock", "trapezoid_profile"]


@attrs.define
class Maneuver:
    name: str
    feasible: bool
    commands: np.ndarray  # (K, 3), one per dt
    dt: float
    reason: str = ""

    @property
    def duration(self) -> float:
        return self.commands.shape[0] * self.dt


def _points(obstacles: LaserScan2D | np.ndarray | None, sensor_pose) -> np.ndarray:
    if obstacles is None:
        raise ValueError("obstacles: maneuvers need a LaserScan (or points) to check free space")
    return obstacle_points(obstacles, sensor_pose)


def free_travel(robot: RobotConfig, points: np.ndarray, direction: float) -> float:
    """How far (m) the footprint can translate along ``direction`` before touching a point.

    The swept footprint is the box itself for BOX robots and the bounding circle otherwise
    (conservative for ellipses).
    """
    if points.shape[0] == 0:
        return math.inf
    c, s = math.cos(direction), math.sin(direction)
    along = points[:, 0] * c + points[:, 1] * s
    lateral = -points[:, 0] * s + points[:, 1] * c
    if robot.geometry_type is RobotGeometry.Type.BOX and abs(math.sin(direction)) < 1e-9:
        half_len, half_w = 0.5 * robot.geometry_params[0], 0.5 * robot.geometry_params[1]
        in_path = np.abs(lateral) <= half_w
        ahead = along[in_path] - half_len
    else:
        r = robot.radius
        in_path = np.abs(lateral) < r
        ahead = along[in_path] - np.sqrt(r * r - lateral[in_path] ** 2)
    ahead = ahead[ahead > -robot.radius]  # points behind the robot do not block this way
    return float(max(ahead.min(), 0.0)) if ahead.size else math.inf


def rotation_is_free(robot: RobotConfig, points: np.ndarray, safety_margin: float) -> bool:
    """Whether nothing lies within the swept circle of the footprint plus ``safety_margin``."""
    if points.shape[0] == 0:
        return True
    return bool(np.min(np.hypot(points[:, 0], points[:, 1])) > robot.radius + safety_margin)


def trapezoid_profile(distance: float, v_max: float, acc: float, dec: float, dt: float) -> np.ndarray:
    """Speeds (one per dt) covering ``distance`` with accel ``acc``, cruise, brake ``dec``."""
    speeds = []
    travelled, v = 0.0, 0.0
    for _ in range(100_000):
        remaining = distance - travelled
        if remaining <= 1e-4:
            break
        # Fastest speed from which braking at dec still stops within the remaining distance.
        v_stop = math.sqrt(2.0 * dec * remaining)
        v = min(v + acc * dt, v_max, v_stop, remaining / dt)
        speeds.append(v)
        travelled += v * dt
    return np.asarray(speeds)


def _translate(name: str, robot: RobotConfig, obstacles, max_distance: float, sign: float, dt: float,
               safety_margin: float, sensor_pose) -> Maneuver:
    pts = _points(obstacles, sensor_pose)
    room = free_travel(robot, pts, 0.0 if sign > 0 else math.pi) - safety_margin
    if room <= 0.01:
        return Maneuver(name, False, np.zeros((0, 3)), dt, f"blocked: {max(room, 0.0):.3f} m free")
    dist = min(max_distance, room)
    lim = robot.ctrl_vx_limits
    v = trapezoid_profile(dist, lim.max_vel, lim.max_acc, lim.max_decel, dt)
    cmds = np.zeros((v.size, 3))
    cmds[:, 0] = sign * v
    reason = "" if dist >= max_distance else f"shortened to {dist:.3f} m by obstacles"
    return Maneuver(name, True, cmds, dt, reason)


def move_forward(robot: RobotConfig, obstacles, max_distance: float = 0.3, dt: float = 0.1,
                 safety_margin: float = 0.05, sensor_pose=(0.0, 0.0, 0.0)) -> Maneuver:
    """Drive straight forward up to ``max_distance`` m, as far as the way is clear."""
    return _translate("move_forward", robot, obstacles, max_distance, 1.0, dt, safety_margin, sensor_pose)


def move_backward(robot: RobotConfig, obstacles, max_distance: float = 0.3, dt: float = 0.1,
                  safety_margin: float = 0.05, sensor_pose=(0.0, 0.0, 0.0)) -> Maneuver:
    """Drive straight backward up to ``max_distance`` m, as far as the way is clear."""
    return _translate("move_backward", robot, obstacles, max_distance, -1.0, dt, safety_margin, sensor_pose)


def rotate_in_place(robot: RobotConfig, obstacles, max_rotation: float = math.pi / 2, dt: float = 0.1,
                    safety_margin: float = 0.1, sensor_pose=(0.0, 0.0, 0.0)) -> Maneuver:
    """Rotate by ``max_rotation`` rad (sign = direction) if the swept circle is clear."""
    if robot.model_type.name == "ACKERMANN":
        return Maneuver("rotate_in_place", False, np.zeros((0, 3)), dt, "an Ackermann robot cannot rotate in place")
    pts = _points(obstacles, sensor_pose)
    if not rotation_is_free(robot, pts, safety_margin):
        return Maneuver("rotate_in_place", False, np.zeros((0, 3)), dt,
                        f"obstacle within {robot.radius + safety_margin:.3f} m of the centre")
    lim = robot.ctrl_omega_limits
    w = trapezoid_profile(abs(max_rotation), lim.max_vel, lim.max_acc, lim.max_decel, dt)
    cmds = np.zeros((w.size, 3))
    cmds[:, 2] = math.copysign(1.0, max_rotation) * w
    return Maneuver("rotate_in_place", True, cmds, dt)


def move_to_unblock(robot: RobotConfig, obstacles, max_distance: float = 0.3,
                    max_rotation: float = math.pi / 2, dt: float = 0.1, safety_margin: float = 0.05,
                    sensor_pose=(0.0, 0.0, 0.0)) -> Maneuver:
    """Try, in order: forward, backward, rotate left, rotate right; the first that is possible.

    A translation only counts if it frees at least half of ``max_distance``, otherwise the
    robot would shuffle against the obstacle; rotations need the swept circle clear.
    """
    attempts = []
    for maneuver in (
        move_forward(robot, obstacles, max_distance, dt, safety_margin, sensor_pose),
        move_backward(robot, obstacles, max_distance, dt, safety_margin, sensor_pose),
    ):
        travel = float(np.sum(np.abs(maneuver.commands[:, 0])) * dt) if maneuver.feasible else 0.0
        if maneuver.feasible and travel >= 0.5 * max_distance - 1e-6:
            return attrs.evolve(maneuver, name=f"move_to_unblock:{maneuver.name}")
        attempts.append(f"{maneuver.name}: {maneuver.reason or f'only {travel:.3f} m free'}")
    for sign in (1.0, -1.0):
        maneuver = rotate_in_place(robot, obstacles, sign * max_rotation, dt, safety_margin, sensor_pose)
        if maneuver.feasible:
            return attrs.evolve(maneuver, name="move_to_unblock:rotate_in_place")
        attempts.append(f"rotate_in_place: {maneuver.reason}")
    return Maneuver("move_to_unblock", False, np.zeros((0, 3)), dt, "; ".join(attempts))
