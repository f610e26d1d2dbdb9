"""A robot placed in a World: kinematic state, command handling and its pybullet bodies."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.geometry import quaternion_of_yaw

from . import _deps
from .robots import RobotSpec, feasible_command, integrate

if TYPE_CHECKING:
    from .dynamics.base import DriveModel
    from .world import World

# The collision box floats this far above the floor so it never touches the ground plane.
GROUND_CLEARANCE = 0.02


@attrs.define(frozen=True)
class Contact:
    """One touching point between a robot and something else, in the world frame."""

    stamp: float
    other: str  # "static", a moving obstacle's name or another robot's name
    position: tuple[float, float, float]
    depth: float  # penetration (m, >= 0)


class SimRobot:
    """A robot in a World. ``command(vx, vy, omega)`` sets the velocity target; each tick its
    drive model (``actors/sim/dynamics``) turns it into motion, which is integrated; then the
    world checks contacts.

    ``drive`` is a :class:`DriveModel` or its name; None = the spec's ``default_drive``. For
    the ideal drive, ``slip`` is the fraction of wheel motion lost to the ground (the body
    moves less than the encoders report, so wheel odometry drifts) and ``actuation_noise`` the
    relative standard deviation of a per-tick random error on the achieved velocity.
    """

    def __init__(self, world: World, spec: RobotSpec, name: str, pose: tuple[float, float, float],
                 slip: float = 0.0, actuation_noise: float = 0.0, rng: np.random.Generator | None = None,
                 drive: DriveModel | str | None = None) -> None:
        from .dynamics import IdealDrive, make_drive

        if not 0.0 <= slip < 1.0:
            raise ValueError(f"SimRobot slip must be in [0, 1), got {slip!r}")
        if actuation_noise < 0:
            raise ValueError(f"SimRobot actuation_noise must be >= 0, got {actuation_noise!r}")
        drive = drive if drive is not None else spec.default_drive
        if drive == "ideal":
            drive = IdealDrive(slip, actuation_noise)
        elif slip or actuation_noise:
            raise ValueError(f"SimRobot slip and actuation_noise belong to the ideal drive; drive {drive!r} models its own")
        self.drive = make_drive(drive)
        self.world, self.spec, self.name = world, spec, name
        self.slip, self.actuation_noise = float(slip), float(actuation_noise)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.pose = np.asarray(pose, dtype=float).copy()
        self.start_pose = self.pose.copy()
        self._previous = self.pose.copy()  # pose before the current tick, restored on contact
        self.twist = np.zeros(3)  # achieved body twist (ground truth)
        self.wheel_twist = np.zeros(3)  # what the wheels turn at (what encoders see)
        self._command = np.zeros(3)
        self._command_stamp = -math.inf
        self.collided = False  # ever touched anything
        self.contacts: list[Contact] = []  # contacts of the last tick
        self.first_contacts: list[Contact] = []  # of the tick that first touched something (where it went wrong)
        self.trail: list[tuple[float, float]] = [(float(pose[0]), float(pose[1]))]
        self.distance_travelled = 0.0
        self.body_id, self.visual_id = self._create_bodies()
        self.drive.bind(spec, self.rng)
        self.drive.reset(self.pose)
        self._place()

    # -- pybullet bodies -------------------------------------------------------------------
    def _create_bodies(self) -> tuple[int, int | None]:
        pb, c, s = _deps.pybullet(), self.world.client, self.spec
        if s.collision:
            col, vis = self._compound_shape()
        elif s.radius > 0:
            col = c.createCollisionShape(pb.GEOM_CYLINDER, radius=s.radius, height=s.height)
            vis = -1 if s.urdf else c.createVisualShape(pb.GEOM_CYLINDER, radius=s.radius, length=s.height, rgbaColor=list(s.color))
        else:
            half = [s.length / 2, s.width / 2, s.height / 2]
            col = c.createCollisionShape(pb.GEOM_BOX, halfExtents=half)
            vis = -1 if s.urdf else c.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=list(s.color))
        # Mass > 0 so Bullet computes its contacts with static obstacles (static-static pairs
        # are skipped); gravity never acts because the world never integrates dynamics.
        body = c.createMultiBody(baseMass=1.0, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis)
        if self.world.ground_id is not None:
            c.setCollisionFilterPair(body, self.world.ground_id, -1, -1, 0)
        visual = None
        if s.urdf:
            c.setAdditionalSearchPath(_deps.pybullet_data_path())
            visual = c.loadURDF(s.urdf, useFixedBase=False)
            # The URDF is looks only: its links must not block rays or cause contacts.
            for link in range(-1, c.getNumJoints(visual)):
                c.setCollisionFilterGroupMask(visual, link, 0, 0)
        return body, visual

    def _compound_shape(self) -> tuple[int, int]:
        """Collision and visual shapes of the spec's parts, relative to a base at half height."""
        pb, c, s = _deps.pybullet(), self.world.client, self.spec
        axle = c.getQuaternionFromEuler([math.pi / 2, 0.0, 0.0])  # cylinder axis (z) onto y
        dims: list[dict[str, Any]]  # keyword arguments of one shape: halfExtents, or radius and height
        kinds, dims, positions, orientations = [], [], [], []
        for part in s.collision:
            x, y, z = part.center
            positions.append([x, y, z - s.height / 2 - GROUND_CLEARANCE])  # parts stay where the spec puts them
            if part.kind == "box":
                kinds.append(pb.GEOM_BOX)
                dims.append(dict(halfExtents=[v / 2 for v in part.size]))
                orientations.append([0, 0, 0, 1])
            else:
                kinds.append(pb.GEOM_CYLINDER)
                dims.append(dict(radius=part.size[0], height=part.size[1]))
                orientations.append(axle)
        col = c.createCollisionShapeArray(
            shapeTypes=kinds, radii=[d.get("radius", 0.0) for d in dims],
            halfExtents=[d.get("halfExtents", [0, 0, 0]) for d in dims], lengths=[d.get("height", 0.0) for d in dims],
            collisionFramePositions=positions, collisionFrameOrientations=orientations)
        vis = -1
        if not s.urdf:
            vis = c.createVisualShapeArray(
                shapeTypes=kinds, radii=[d.get("radius", 0.0) for d in dims],
                halfExtents=[d.get("halfExtents", [0, 0, 0]) for d in dims], lengths=[d.get("height", 0.0) for d in dims],
                visualFramePositions=positions, visualFrameOrientations=orientations, rgbaColors=[list(s.color)] * len(kinds))
        return col, vis

    def _place(self) -> None:
        c, (x, y, yaw), s = self.world.client, self.pose, self.spec
        cx, cy = x + s.center_offset * math.cos(yaw), y + s.center_offset * math.sin(yaw)
        c.resetBasePositionAndOrientation(self.body_id, [cx, cy, GROUND_CLEARANCE + s.height / 2], quaternion_of_yaw(yaw))
        if self.visual_id is not None:
            c.resetBasePositionAndOrientation(self.visual_id, [x, y, 0.0], quaternion_of_yaw(yaw))

    # -- commands and kinematics -------------------------------------------------------------
    def command(self, vx: float, vy: float = 0.0, omega: float = 0.0) -> None:
        """Set the velocity target (body frame); clipped to the robot's limits."""
        values = np.array([vx, vy, omega], dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"SimRobot.command needs finite (vx, vy, omega), got {values.tolist()!r}")
        self._command = feasible_command(self.spec, *values)
        self._command_stamp = self.world.clock.now()

    @property
    def commanded(self) -> np.ndarray:
        return self._command.copy()

    def reset(self, pose: tuple[float, float, float] | None = None) -> None:
        self.pose = np.asarray(pose if pose is not None else self.start_pose, dtype=float).copy()
        self._previous = self.pose.copy()
        self.twist[:] = 0.0
        self.wheel_twist[:] = 0.0
        self._command[:] = 0.0
        self._command_stamp = -math.inf
        self.drive.reset(self.pose)
        self.collided = False
        self.contacts = []
        self.first_contacts = []
        self.trail = [(float(self.pose[0]), float(self.pose[1]))]
        self.distance_travelled = 0.0
        self._place()

    def advance(self, dt: float) -> None:
        """Move one tick (called by the World before it checks contacts)."""
        self._previous = self.pose.copy()
        command = self._command
        timeout = self.drive.command_timeout
        if timeout is not None and self.world.clock.now() - self._command_stamp > timeout + 1e-9:
            command = np.zeros(3)  # the base's watchdog: a stale command is a stop
        self.twist, self.wheel_twist = self.drive.step(command, dt)
        self.pose = integrate(self.pose, self.twist, dt)
        self._place()

    def resolve_contacts(self, stamp: float, points: list[Any], names: dict[int, str]) -> None:
        """Keep penetrating contacts; on a new one, stop where the robot was before the tick."""
        touching = [p for p in points if p[8] <= 0.0]
        self.contacts = [
            Contact(stamp, names.get(p[2], "static"), tuple(p[5]), float(-p[8])) for p in touching
        ]
        if touching:
            if not self.collided:
                self.first_contacts = list(self.contacts)
            self.collided = True
            self.pose = self._previous.copy()
            self.twist = np.zeros(3)
            self.wheel_twist = np.zeros(3)
            self.drive.halt(self.pose)
            self._place()
        step = math.dist(self.trail[-1], self.pose[:2])
        if step > 0.02:  # keep the trail light: one point per 2 cm
            self.distance_travelled += step
            self.trail.append((float(self.pose[0]), float(self.pose[1])))
