"""Robot model: motion model, collision geometry, control limits and coordinate frames.

Everything here is validated at construction so that a wrong parameter array or an impossible
limit fails where the robot is declared, not deep inside a controller loop.
"""
from __future__ import annotations

import enum
import math
from typing import Any, ClassVar

import attrs
import numpy as np

from emos.config import validators as V

__all__ = [
    "RobotType",
    "RobotGeometry",
    "LinearCtrlLimits",
    "AngularCtrlLimits",
    "RobotConfig",
    "RobotFrames",
]


class RobotType(enum.Enum):
    """Kinematic (motion) model of the drivetrain."""

    ACKERMANN = "ACKERMANN"  # car-like bicycle model: steering limited, no spin in place
    DIFFERENTIAL_DRIVE = "DIFFERENTIAL_DRIVE"  # forward/backward and spin in place
    OMNI = "OMNI"  # holonomic: vx, vy and omega independent

    @classmethod
    def from_any(cls, value: RobotType | str) -> RobotType:
        if isinstance(value, cls):
            return value
        if isinstance(value, str) and value.upper() in cls.__members__:
            return cls[value.upper()]
        raise ValueError(
            f"model_type: expected one of {[m.name for m in cls]}, got {value!r}"
        )


class _GeometryType(enum.Enum):
    BOX = "BOX"
    CYLINDER = "CYLINDER"
    SPHERE = "SPHERE"
    ELLIPSOID = "ELLIPSOID"
    CAPSULE = "CAPSULE"
    CONE = "CONE"


class RobotGeometry:
    """Collision geometry of the robot body, centred on ``robot_base``.

    ``RobotGeometry.Type`` names the shape; the parameter arrays are:

    ========== ============================ =================================================
    BOX        ``[length, width, height]``  full edge lengths along x, y, z
    CYLINDER   ``[radius, length_z]``       vertical cylinder
    SPHERE     ``[radius]``
    ELLIPSOID  ``[axis_x, axis_y, axis_z]`` semi-axes (as python-fcl's ``Ellipsoid``)
    CAPSULE    ``[radius, length_z]``       cylinder with hemispherical ends
    CONE       ``[radius, length_z]``       vertical cone, ``radius`` at its base
    ========== ============================ =================================================

    The 2D footprint used by local planning and safety is the shape's widest horizontal
    cross-section: a rectangle for BOX, an ellipse for ELLIPSOID, a circle otherwise.
    """

    Type = _GeometryType

    PARAM_NAMES: ClassVar[dict[_GeometryType, tuple[str, ...]]] = {
        _GeometryType.BOX: ("length", "width", "height"),
        _GeometryType.CYLINDER: ("radius", "length_z"),
        _GeometryType.SPHERE: ("radius",),
        _GeometryType.ELLIPSOID: ("axis_x", "axis_y", "axis_z"),
        _GeometryType.CAPSULE: ("radius", "length_z"),
        _GeometryType.CONE: ("radius", "length_z"),
    }

    @classmethod
    def get_type(cls, value: _GeometryType | str) -> _GeometryType:
        if isinstance(value, _GeometryType):
            return value
        if isinstance(value, str) and value.upper() in _GeometryType.__members__:
            return _GeometryType[value.upper()]
        raise ValueError(
            f"geometry_type: expected one of {[t.name for t in _GeometryType]}, got {value!r}"
        )

    @classmethod
    def validate_params(cls, geometry_type: _GeometryType | str, params: Any) -> np.ndarray:
        """Return ``params`` as a float64 array, or raise naming the expected layout."""
        gtype = cls.get_type(geometry_type)
        names = cls.PARAM_NAMES[gtype]
        try:
            arr = np.asarray(params, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"geometry_params for {gtype.name}: expected numbers [{', '.join(names)}], "
                f"got {params!r}"
            ) from exc
        if arr.size != len(names):
            raise ValueError(
                f"geometry_params for {gtype.name}: expected {len(names)} values "
                f"[{', '.join(names)}], got {arr.size}: {arr.tolist()}"
            )
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
            raise ValueError(
                f"geometry_params for {gtype.name}: every value of [{', '.join(names)}] must be "
                f"finite and > 0, got {arr.tolist()}"
            )
        return arr

    @classmethod
    def radius(cls, geometry_type: _GeometryType | str, params: Any) -> float:
        """Radius of the smallest circle around ``robot_base`` containing the 2D footprint."""
        gtype = cls.get_type(geometry_type)
        p = cls.validate_params(gtype, params)
        if gtype is _GeometryType.BOX:
            return float(math.hypot(p[0] / 2.0, p[1] / 2.0))
        if gtype is _GeometryType.ELLIPSOID:
            return float(max(p[0], p[1]))
        return float(p[0])

    @classmethod
    def inner_radius(cls, geometry_type: _GeometryType | str, params: Any) -> float:
        """Radius of the largest circle around ``robot_base`` inside the 2D footprint."""
        gtype = cls.get_type(geometry_type)
        p = cls.validate_params(gtype, params)
        if gtype is _GeometryType.BOX:
            return float(min(p[0], p[1]) / 2.0)
        if gtype is _GeometryType.ELLIPSOID:
            return float(min(p[0], p[1]))
        return float(p[0])

    @classmethod
    def height(cls, geometry_type: _GeometryType | str, params: Any) -> float:
        """Full vertical extent of the body."""
        gtype = cls.get_type(geometry_type)
        p = cls.validate_params(gtype, params)
        if gtype is _GeometryType.BOX:
            return float(p[2])
        if gtype is _GeometryType.SPHERE:
            return float(2.0 * p[0])
        if gtype is _GeometryType.ELLIPSOID:
            return float(2.0 * p[2])
        if gtype is _GeometryType.CAPSULE:
            return float(p[1] + 2.0 * p[0])
        return float(p[1])

    @classmethod
    def footprint_distance(
        cls, geometry_type: _GeometryType | str, params: Any, points: np.ndarray
    ) -> np.ndarray:
        """Distance from each 2D point (robot frame, shape (..., 2)) to the footprint edge.

        Negative inside the footprint. Vectorized over any leading shape.
        """
        gtype = cls.get_type(geometry_type)
        p = cls.validate_params(gtype, params)
        pts = np.asarray(points)
        x = pts[..., 0]
        y = pts[..., 1]
        if gtype is _GeometryType.BOX:
            # Signed distance of an axis-aligned rectangle.
            qx = np.abs(x) - p[0] / 2.0
            qy = np.abs(y) - p[1] / 2.0
            outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
            inside = np.minimum(np.maximum(qx, qy), 0.0)
            return outside + inside
        if gtype is _GeometryType.ELLIPSOID:
            return _ellipse_distance(x, y, float(p[0]), float(p[1]))
        return np.hypot(x, y) - p[0]


def _ellipse_distance(x: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    """Signed distance to an axis-aligned ellipse with semi-axes a, b (vectorized).

    Uses a few fixed-point iterations on the closest-point parameter, which converge to well
    under a millimetre for robot-sized ellipses; no per-point Python loop.
    """
    px = np.abs(x)
    py = np.abs(y)
    tx = np.full_like(px, 0.70710678)
    ty = np.full_like(py, 0.70710678)
    for _ in range(4):
        ex = (a * a - b * b) * tx**3 / a
        ey = (b * b - a * a) * ty**3 / b
        rx = a * tx - ex
        ry = b * ty - ey
        qx = px - ex
        qy = py - ey
        r = np.hypot(ry, rx)
        q = np.hypot(qy, qx)
        q = np.where(q == 0.0, 1e-12, q)
        tx = np.clip((qx * r / q + ex) / a, 0.0, 1.0)
        ty = np.clip((qy * r / q + ey) / b, 0.0, 1.0)
        t = np.hypot(tx, ty)
        t = np.where(t == 0.0, 1.0, t)
        tx = tx / t
        ty = ty / t
    dist = np.hypot(px - a * tx, py - b * ty)
    inside = (px / a) ** 2 + (py / b) ** 2 < 1.0
    return np.where(inside, -dist, dist)


def _to_robot_type(value: RobotType | str) -> RobotType:
    return RobotType.from_any(value)


def _to_geometry_type(value: _GeometryType | str) -> _GeometryType:
    return RobotGeometry.get_type(value)


@attrs.define(frozen=True)
class LinearCtrlLimits:
    """Limits on one linear velocity axis (m/s, m/s^2).

    ``max_decel`` is separate from ``max_acc`` so braking can be harder than speeding up.
    ``max_vel`` may be 0 to disable an axis (e.g. lateral motion of a non-omni robot).
    """

    max_vel: float = attrs.field(converter=float, validator=V.number(ge=0, finite=True, what="a finite speed"))
    max_acc: float = attrs.field(converter=float, validator=V.number(gt=0, finite=True, what="a finite acceleration"))
    max_decel: float = attrs.field(converter=float, validator=V.number(gt=0, finite=True, what="a finite deceleration"))


@attrs.define(frozen=True)
class AngularCtrlLimits:
    """Limits on rotation (rad/s, rad/s^2) and the steering angle of Ackermann robots (rad)."""

    max_vel: float = attrs.field(converter=float, validator=V.number(ge=0, finite=True, what="a finite angular speed"))
    max_acc: float = attrs.field(converter=float, validator=V.number(gt=0, finite=True, what="a finite angular acceleration"))
    max_decel: float = attrs.field(converter=float, validator=V.number(gt=0, finite=True, what="a finite angular deceleration"))
    max_steer: float = attrs.field(default=math.pi / 3, converter=float)

    @max_steer.validator
    def _check_steer(self, attribute: attrs.Attribute, value: float) -> None:
        if not (0.0 < value < math.pi / 2):
            raise ValueError(
                f"AngularCtrlLimits.max_steer: expected a steering angle in (0, pi/2) rad, "
                f"got {value!r}"
            )


def _default_vx() -> LinearCtrlLimits:
    return LinearCtrlLimits(max_vel=1.0, max_acc=1.5, max_decel=2.5)


def _default_vy() -> LinearCtrlLimits:
    return LinearCtrlLimits(max_vel=0.5, max_acc=0.7, max_decel=3.5)


def _default_omega() -> AngularCtrlLimits:
    return AngularCtrlLimits(max_vel=1.0, max_acc=2.0, max_decel=2.0, max_steer=math.pi / 3)


@attrs.define(frozen=True, eq=False)
class RobotConfig:
    """The robot's digital twin: motion model, geometry and control limits.

    ``ctrl_vy_limits`` is only used by OMNI robots; the other models never command vy.
    ``wheel_base`` (m, Ackermann only): 0 derives it from the footprint, its length for a
    BOX and its inner diameter otherwise.
    """

    model_type: RobotType = attrs.field(converter=_to_robot_type)
    geometry_type: _GeometryType = attrs.field(converter=_to_geometry_type)
    geometry_params: np.ndarray = attrs.field()
    ctrl_vx_limits: LinearCtrlLimits = attrs.field(factory=_default_vx, validator=V.instance_of(LinearCtrlLimits))
    ctrl_vy_limits: LinearCtrlLimits = attrs.field(factory=_default_vy, validator=V.instance_of(LinearCtrlLimits))
    ctrl_omega_limits: AngularCtrlLimits = attrs.field(factory=_default_omega, validator=V.instance_of(AngularCtrlLimits))
    wheel_base: float = attrs.field(default=0.0, converter=float)

    def __attrs_post_init__(self) -> None:
        params = RobotGeometry.validate_params(self.geometry_type, self.geometry_params)
        params.setflags(write=False)
        object.__setattr__(self, "geometry_params", params)
        if self.wheel_base == 0.0:
            if self.geometry_type is RobotGeometry.Type.BOX:
                wb = float(params[0])
            else:
                wb = 2.0 * RobotGeometry.inner_radius(self.geometry_type, params)
            object.__setattr__(self, "wheel_base", wb)
        elif not (math.isfinite(self.wheel_base) and self.wheel_base > 0):
            raise ValueError(f"RobotConfig.wheel_base: expected a finite length > 0 m "
                             f"(or 0 to derive it from the geometry), got {self.wheel_base!r}")
        if self.ctrl_vx_limits.max_vel <= 0:
            raise ValueError("RobotConfig.ctrl_vx_limits.max_vel: a robot must be able to move "
                             f"forward, expected > 0, got {self.ctrl_vx_limits.max_vel}")
        if self.model_type is not RobotType.ACKERMANN and self.ctrl_omega_limits.max_vel <= 0:
            raise ValueError("RobotConfig.ctrl_omega_limits.max_vel: expected > 0 rad/s for a "
                             f"{self.model_type.name} robot, got {self.ctrl_omega_limits.max_vel}")

    @property
    def radius(self) -> float:
        """Bounding radius of the 2D footprint (m)."""
        return RobotGeometry.radius(self.geometry_type, self.geometry_params)

    @property
    def inner_radius(self) -> float:
        return RobotGeometry.inner_radius(self.geometry_type, self.geometry_params)

    @property
    def height(self) -> float:
        return RobotGeometry.height(self.geometry_type, self.geometry_params)

    @property
    def max_curvature(self) -> float:
        """Largest path curvature (1/m) the robot can follow while moving (inf if it can spin)."""
        if self.model_type is RobotType.ACKERMANN:
            return math.tan(self.ctrl_omega_limits.max_steer) / self.wheel_base
        return math.inf

    def footprint_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of robot-frame 2D points to the footprint edge (negative inside)."""
        return RobotGeometry.footprint_distance(self.geometry_type, self.geometry_params, points)


@attrs.define(frozen=True)
class RobotFrames:
    """Names of the coordinate frames the navigation components look up."""

    world: str = attrs.field(default="map", validator=V.non_empty_str)
    odom: str = attrs.field(default="odom", validator=V.non_empty_str)
    robot_base: str = attrs.field(default="base_link", validator=V.non_empty_str)
    scan: str = attrs.field(default="scan", validator=V.non_empty_str)
    rgb: str = attrs.field(default="camera/rgb", validator=V.non_empty_str)
    depth: str = attrs.field(default="camera/depth", validator=V.non_empty_str)
