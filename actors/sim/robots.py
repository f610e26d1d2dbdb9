"""Robot models: dimensions, drive type and command limits, plus pure kinematics.

Choice: robots are **kinematic** bases. Each tick the commanded velocity is limited (speed and
acceleration), optionally perturbed (slip, actuation noise) and integrated exactly; the body is
then posed in pybullet, which only answers collision, ray and render queries. Wheel-contact
physics would cost ~10x more per tick, make results depend on friction tuning, and is not what
navigation benchmarks (BARN included) measure; a collision is detected from contact queries and
stops the robot where it touched.
"""
from __future__ import annotations

import enum
import math
from collections.abc import Iterable

import attrs
import numpy as np

from emos.config import validators as V
from emos.geometry import integrate_pose


class DriveType(str, enum.Enum):
    DIFFERENTIAL = "differential"
    ACKERMANN = "ackermann"
    OMNI = "omni"


@attrs.define(frozen=True)
class CollisionPart:
    """One piece of a compound collision shape, in the base frame (z from the floor): a box
    (``size`` = length, width, height) or a wheel (a cylinder whose axis is the y axis,
    ``size`` = radius, width, unused)."""

    kind: str = attrs.field(validator=attrs.validators.in_(("box", "wheel")))
    center: tuple[float, float, float] = attrs.field(converter=lambda v: tuple(float(x) for x in v))
    size: tuple[float, float, float] = attrs.field(converter=lambda v: tuple(float(x) for x in v))

    def __attrs_post_init__(self) -> None:
        if len(self.center) != 3 or len(self.size) != 3 or not all(math.isfinite(v) for v in self.center):
            raise ValueError(f"CollisionPart needs a 3D center and size, got {self.center!r}, {self.size!r}")
        if any(v <= 0 for v in (self.size if self.kind == "box" else self.size[:2])):
            raise ValueError(f"CollisionPart {self.kind} size must be positive, got {self.size!r}")

    def extent(self) -> tuple[float, float]:
        """Half extents (x, y) of the part's footprint."""
        if self.kind == "box":
            return self.size[0] / 2, self.size[1] / 2
        return self.size[0], self.size[1] / 2


def _parts(value: Iterable[CollisionPart]) -> tuple[CollisionPart, ...]:
    """Converter of ``RobotSpec.collision`` (a typed ``tuple``)."""
    return tuple(value)


@attrs.define(frozen=True)
class RobotSpec:
    """What a simulated robot is: footprint box, drive and limits (SI units)."""

    name: str
    drive: DriveType = attrs.field(converter=DriveType)
    length: float = attrs.field(converter=float, validator=V.finite_positive)
    width: float = attrs.field(converter=float, validator=V.finite_positive)
    height: float = attrs.field(converter=float, validator=V.finite_positive)
    max_vx: float = attrs.field(converter=float, validator=V.finite_positive)
    max_omega: float = attrs.field(converter=float, validator=V.finite_positive)
    max_acc_x: float = attrs.field(converter=float, validator=V.finite_positive)
    max_acc_omega: float = attrs.field(converter=float, validator=V.finite_positive)
    max_vy: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    max_acc_y: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    # Ackermann only: axle distance and steering limit.
    wheelbase: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    max_steer: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    # Offset of the footprint centre ahead of the base frame origin (racecar: rear axle).
    center_offset: float = attrs.field(default=0.0, converter=float)
    urdf: str | None = None  # pybullet_data-relative visual model, if any
    lidar_height: float = attrs.field(default=0.3, converter=float, validator=V.finite_positive)
    color: tuple[float, float, float, float] = (0.15, 0.3, 0.8, 1.0)
    # > 0: the body is a vertical cylinder of this radius (length and width are its diameter).
    radius: float = attrs.field(default=0.0, converter=float, validator=V.finite_non_negative)
    # Non-empty: the collision shape is these parts (the official Jackal: chassis box and four
    # wheels), centred on the base frame; length and width must be their bounding box.
    collision: tuple[CollisionPart, ...] = attrs.field(default=(), converter=_parts)
    # The drive model a robot of this spec gets unless told otherwise (see actors/sim/dynamics).
    default_drive: str = "ideal"

    def __attrs_post_init__(self) -> None:
        if self.drive is DriveType.OMNI and not (self.max_vy > 0 and self.max_acc_y > 0):
            raise ValueError(f"RobotSpec {self.name!r}: an omni robot needs max_vy and max_acc_y > 0")
        if self.drive is DriveType.ACKERMANN and not (self.wheelbase > 0 and self.max_steer > 0):
            raise ValueError(f"RobotSpec {self.name!r}: an Ackermann robot needs wheelbase and max_steer > 0")
        if self.radius > 0 and not (abs(self.length - 2 * self.radius) < 1e-9 and abs(self.width - 2 * self.radius) < 1e-9):
            raise ValueError(f"RobotSpec {self.name!r}: a cylinder robot's length and width must be 2 * radius")
        if self.collision:
            hx = max(abs(p.center[0]) + p.extent()[0] for p in self.collision)
            hy = max(abs(p.center[1]) + p.extent()[1] for p in self.collision)
            if abs(2 * hx - self.length) > 1e-6 or abs(2 * hy - self.width) > 1e-6:
                raise ValueError(f"RobotSpec {self.name!r}: length x width must be the collision parts' bounding box "
                                 f"({2 * hx:.4f} x {2 * hy:.4f} m)")

    @property
    def circumscribed_radius(self) -> float:
        return math.hypot(self.length / 2, self.width / 2)

    def footprint(self) -> np.ndarray:
        """Footprint corners (4, 2) in the base frame (of the bounding box for a cylinder)."""
        hx, hy, c = self.length / 2, self.width / 2, self.center_offset
        return np.array([[c + hx, hy], [c - hx, hy], [c - hx, -hy], [c + hx, -hy]])


# Clearpath Jackal as used by BARN: 0.508 x 0.430 m, 2.0 m/s; speed and acceleration limits
# of its stock diff-drive controller (jackal_control: 2 m/s, 4 rad/s, 20 m/s^2, 25 rad/s^2).
JACKAL = RobotSpec(
    name="jackal", drive="differential", length=0.508, width=0.430, height=0.25,
    max_vx=2.0, max_omega=4.0, max_acc_x=20.0, max_acc_omega=25.0, lidar_height=0.3,
)
# TurtleBot3 Burger: 138 x 178 mm, 0.22 m/s, 2.84 rad/s.
TURTLEBOT3 = RobotSpec(
    name="turtlebot3", drive="differential", length=0.138, width=0.178, height=0.19,
    max_vx=0.22, max_omega=2.84, max_acc_x=2.5, max_acc_omega=3.2, lidar_height=0.2,
    color=(0.2, 0.2, 0.2, 1.0),
)
# TurtleBot3 Waffle Pi: 281 x 306 mm, 0.26 m/s, 1.82 rad/s.
TURTLEBOT3_WAFFLE_PI = RobotSpec(
    name="turtlebot3_waffle_pi", drive="differential", length=0.281, width=0.306, height=0.141,
    max_vx=0.26, max_omega=1.82, max_acc_x=2.5, max_acc_omega=3.2, lidar_height=0.17,
    color=(0.25, 0.25, 0.25, 1.0),
)
# pybullet_data's MIT racecar (1:10): base frame on the rear axle, wheelbase 0.325 m; the box
# covers its links' extent (x from -0.05 to 0.41 m, wheels at +-0.147 m).
RACECAR = RobotSpec(
    name="racecar", drive="ackermann", length=0.47, width=0.30, height=0.12,
    max_vx=3.0, max_omega=6.0, max_acc_x=4.0, max_acc_omega=20.0, wheelbase=0.325, max_steer=0.5,
    center_offset=0.18, urdf="racecar/racecar.urdf", lidar_height=0.2, color=(0.8, 0.2, 0.2, 1.0),
)
HOLONOMIC = RobotSpec(
    name="holonomic", drive="omni", length=0.5, width=0.5, height=0.25,
    max_vx=1.0, max_vy=1.0, max_omega=2.0, max_acc_x=2.0, max_acc_y=2.0, max_acc_omega=4.0,
    color=(0.2, 0.6, 0.3, 1.0),
)
# The Jackal as the BARN simulator models it: the official description's collision shape (a
# 0.42 x 0.31 m chassis box and four wheels, r 0.098 m, 0.04 m wide, at (+-0.131, +-0.1878) m;
# the fenders do not collide), the diff-drive controller's limits, and a drive model:
# ``jackal-barn`` the calibrated skid-steer model, ``jackal-wheeled`` pybullet wheels.
JACKAL_WHEEL_RADIUS = 0.098
JACKAL_COLLISION = (
    CollisionPart("box", (0.0, 0.0, JACKAL_WHEEL_RADIUS), (0.42, 0.31, 0.184)),
    *(CollisionPart("wheel", (sx * 0.131, sy * 0.1878, JACKAL_WHEEL_RADIUS), (JACKAL_WHEEL_RADIUS, 0.04, 0.0))
      for sx in (1, -1) for sy in (1, -1)),
)
JACKAL_BARN = attrs.evolve(JACKAL, name="jackal-barn", length=2 * (0.131 + JACKAL_WHEEL_RADIUS), width=2 * (0.1878 + 0.02),
                           height=0.184 + JACKAL_WHEEL_RADIUS, collision=JACKAL_COLLISION, default_drive="skid-steer")
JACKAL_WHEELED = attrs.evolve(JACKAL_BARN, name="jackal-wheeled", default_drive="wheeled")
PRESETS: dict[str, RobotSpec] = {s.name: s for s in (JACKAL, JACKAL_BARN, JACKAL_WHEELED, TURTLEBOT3, TURTLEBOT3_WAFFLE_PI,
                                                     RACECAR, HOLONOMIC)}
PRESETS["turtlebot3_burger"] = TURTLEBOT3  # the TurtleBot3 model's full name


def robot_spec(name_or_spec: str | RobotSpec) -> RobotSpec:
    if isinstance(name_or_spec, RobotSpec):
        return name_or_spec
    try:
        return PRESETS[name_or_spec]
    except KeyError:
        raise ValueError(f"unknown robot {name_or_spec!r}; expected one of {sorted(PRESETS)}") from None


def feasible_command(spec: RobotSpec, vx: float, vy: float, omega: float) -> np.ndarray:
    """The commanded body twist clipped to what the drive can do (no acceleration limit)."""
    vx = float(np.clip(vx, -spec.max_vx, spec.max_vx))
    omega = float(np.clip(omega, -spec.max_omega, spec.max_omega))
    if spec.drive is DriveType.OMNI:
        vy = float(np.clip(vy, -spec.max_vy, spec.max_vy))
    else:
        vy = 0.0
    if spec.drive is DriveType.ACKERMANN:
        # A car turns only while moving: the curvature is bounded by the steering limit.
        max_curv = math.tan(spec.max_steer) / spec.wheelbase
        omega = float(np.clip(omega, -abs(vx) * max_curv, abs(vx) * max_curv))
    return np.array([vx, vy, omega])


def accelerate(spec: RobotSpec, current: np.ndarray, target: np.ndarray, dt: float) -> np.ndarray:
    """Move ``current`` (vx, vy, omega) toward ``target`` within the acceleration limits."""
    limits = np.array([spec.max_acc_x, spec.max_acc_y, spec.max_acc_omega]) * dt
    out = current + np.clip(target - current, -limits, limits)
    if spec.drive is DriveType.ACKERMANN:
        out = feasible_command(spec, *out)  # keep curvature feasible while the speed ramps
    return out


def integrate(pose: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
    """Exact constant-twist integration of (x, y, yaw) over ``dt`` (arcs, not straight steps):
    :func:`emos.geometry.integrate_pose`, the same one the navigation stack predicts with."""
    return integrate_pose(pose, twist, dt)
