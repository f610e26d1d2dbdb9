"""A wheeled Jackal in pybullet dynamics: four friction wheels on velocity motors.

The reference the skid-steer model (``skid_steer.py``) is calibrated against, and a robot of
its own (``jackal-wheeled``). It lives in a private pybullet client (a plane and the robot,
nothing else), so obstacles, rays and contacts stay in the World's kinematic scene: each
tick the World re-poses its collision body where this simulation says the robot went.

Geometry and limits from the official Jackal description and control configuration
(see /work/shared/benchmarks/barn/README.md): wheel radius 0.098 m and width 0.04 m at
(+-0.131, +-0.1878) m, about 17 kg, friction 0.5, diff-drive controller with 2.0 m/s,
20 m/s^2, 4.0 rad/s, 25 rad/s^2 and ``wheel_separation_multiplier`` 1.5.

The yaw response of a skid-steer base in a rigid-body engine depends strongly on the solver
settings (measured: 0.4 to 1.1 of the commanded yaw rate across step sizes and solvers), so
they are fixed here (:data:`PHYSICS`) and the tests pin the responses they give.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from .. import _deps
from ..robots import accelerate
from .base import DriveModel, twist_between


@attrs.define(frozen=True)
class JackalGeometry:
    wheel_radius: float = 0.098
    wheel_width: float = 0.04
    wheel_x: float = 0.131  # half the wheelbase (0.262 m)
    wheel_y: float = 0.1878  # half the track (0.37559 m)
    chassis: tuple[float, float, float] = (0.42, 0.31, 0.184)
    chassis_mass: float = 15.2
    wheel_mass: float = 0.477
    friction: float = 0.5
    separation_multiplier: float = 1.5

    @property
    def mass(self) -> float:
        return self.chassis_mass + 4 * self.wheel_mass


@attrs.define(frozen=True)
class PhysicsSettings:
    """The fixed engine settings the calibration holds for (change them and re-run the
    calibration tests: the turn response moves with them)."""

    time_step: float = 0.002
    solver_iterations: int = 50
    wheel_torque: float = 10.0  # N m per wheel: well above what friction lets the wheels transmit
    # Cone friction and a soft wheel contact: without them the scrubbing wheels of a turning
    # skid-steer base hop (stick-slip, up to 0.25 m at 1 ms steps) and the turn response
    # swings with the step size; with them the body stays within 2 cm of the ground.
    cone_friction: bool = True
    contact_stiffness: float = 3.0e4
    contact_damping: float = 1.0e3
    gravity: float = 9.81


PHYSICS = PhysicsSettings()
JACKAL_GEOMETRY = JackalGeometry()


class WheeledJackal(DriveModel):
    """Drive model backed by a private pybullet simulation of the wheeled Jackal."""

    name = "wheeled"
    command_timeout = 0.25

    def __init__(self, geometry: JackalGeometry = JACKAL_GEOMETRY, physics: PhysicsSettings = PHYSICS) -> None:
        self.geometry, self.physics = geometry, physics
        self._client: Any = None
        self._controller = np.zeros(3)  # the diff-drive controller's limited output
        self._pose = np.zeros(3)
        self._wheel_twist = np.zeros(3)
        self._sub_dt = 0.0

    # -- the private scene -------------------------------------------------------------------
    def _build(self) -> None:
        pb = _deps.pybullet()
        with _deps.c_stdout_silenced():
            self._client = _deps.bullet_client()(connection_mode=pb.DIRECT)
        c, g, ph = self._client, self.geometry, self.physics
        c.setGravity(0, 0, -ph.gravity)
        c.setPhysicsEngineParameter(fixedTimeStep=ph.time_step, numSolverIterations=ph.solver_iterations,
                                    numSubSteps=0, enableConeFriction=int(ph.cone_friction))
        c.setAdditionalSearchPath(_deps.pybullet_data_path())
        self._plane = c.loadURDF("plane.urdf")
        # Bullet multiplies the two bodies' friction coefficients: the plane is 1, the wheels mu.
        c.changeDynamics(self._plane, -1, lateralFriction=1.0, rollingFriction=0.0, spinningFriction=0.0)
        lx, ly, lz = g.chassis
        chassis = c.createCollisionShape(pb.GEOM_BOX, halfExtents=[lx / 2, ly / 2, lz / 2])
        axis_y = c.getQuaternionFromEuler([math.pi / 2, 0, 0])  # cylinder axis (z) onto the axle (y)
        wheel = c.createCollisionShape(pb.GEOM_CYLINDER, radius=g.wheel_radius, height=g.wheel_width,
                                       collisionFrameOrientation=axis_y)
        # The base frame sits on the axle plane; the chassis box above it clears the ground.
        positions = [[sx * g.wheel_x, sy * g.wheel_y, 0.0] for sx in (1, -1) for sy in (1, -1)]
        self._body = c.createMultiBody(
            baseMass=g.chassis_mass, baseCollisionShapeIndex=chassis,
            baseInertialFramePosition=[0, 0, 0.03],
            basePosition=[0, 0, g.wheel_radius], baseOrientation=[0, 0, 0, 1],
            linkMasses=[g.wheel_mass] * 4, linkCollisionShapeIndices=[wheel] * 4, linkVisualShapeIndices=[-1] * 4,
            linkPositions=positions, linkOrientations=[[0, 0, 0, 1]] * 4,
            linkInertialFramePositions=[[0, 0, 0]] * 4, linkInertialFrameOrientations=[[0, 0, 0, 1]] * 4,
            linkParentIndices=[0] * 4, linkJointTypes=[pb.JOINT_REVOLUTE] * 4, linkJointAxis=[[0, 1, 0]] * 4,
        )
        for link in range(4):
            c.changeDynamics(self._body, link, lateralFriction=g.friction, rollingFriction=0.0, spinningFriction=0.0,
                             contactStiffness=ph.contact_stiffness, contactDamping=ph.contact_damping)
        c.changeDynamics(self._body, -1, lateralFriction=g.friction)
        self._left = [i for i, p in enumerate(positions) if p[1] > 0]
        self._right = [i for i, p in enumerate(positions) if p[1] < 0]

    def _ensure(self) -> None:
        if self._client is None:
            self._build()

    # -- DriveModel ------------------------------------------------------------------------------
    def reset(self, pose: np.ndarray) -> None:
        self._ensure()
        c, g = self._client, self.geometry
        x, y, yaw = (float(v) for v in pose)
        c.resetBasePositionAndOrientation(self._body, [x, y, g.wheel_radius], c.getQuaternionFromEuler([0, 0, yaw]))
        c.resetBaseVelocity(self._body, [0, 0, 0], [0, 0, 0])
        for link in range(4):
            c.resetJointState(self._body, link, 0.0, 0.0)
        self._controller[:] = 0.0
        self._wheel_twist[:] = 0.0
        # Settle the suspension-less contact once so the first tick does not start with a drop.
        for _ in range(int(round(0.1 / self.physics.time_step))):
            self._motors(0.0, 0.0)
            c.stepSimulation()
        self._pose = self._read_pose()

    def halt(self, pose: np.ndarray) -> None:
        self.reset(pose)

    def _read_pose(self) -> np.ndarray:
        (x, y, _), q = self._client.getBasePositionAndOrientation(self._body)
        yaw = self._client.getEulerFromQuaternion(q)[2]
        return np.array([x, y, yaw])

    def _motors(self, left: float, right: float) -> None:
        pb = _deps.pybullet()
        torque = self.physics.wheel_torque
        for links, speed in ((self._left, left), (self._right, right)):
            self._client.setJointMotorControlArray(self._body, links, pb.VELOCITY_CONTROL,
                                                   targetVelocities=[speed] * len(links), forces=[torque] * len(links))

    def step(self, command: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        self._ensure()
        g, ph = self.geometry, self.physics
        self._controller = accelerate(self.spec, self._controller, np.array([command[0], 0.0, command[2]]), dt)
        v, w = self._controller[0], self._controller[2]
        half = g.separation_multiplier * g.wheel_y  # the controller's effective half track
        left, right = (v - w * half) / g.wheel_radius, (v + w * half) / g.wheel_radius
        self._motors(left, right)
        n = max(1, int(round(dt / ph.time_step)))
        for _ in range(n):
            self._client.stepSimulation()
        pose0, self._pose = self._pose, self._read_pose()
        body = twist_between(pose0, self._pose, dt)
        # Encoders: the mean wheel speeds, through the controller's own odometry formula.
        speeds = [s[1] for s in self._client.getJointStates(self._body, range(4))]
        wl = float(np.mean([speeds[i] for i in self._left]))
        wr = float(np.mean([speeds[i] for i in self._right]))
        self._wheel_twist = np.array([g.wheel_radius * (wl + wr) / 2, 0.0, g.wheel_radius * (wr - wl) / (2 * half)])
        return body, self._wheel_twist.copy()

    def close(self) -> None:
        if self._client is not None:
            try:
                self._client.disconnect()
            finally:
                self._client = None

    def describe(self) -> dict:
        return {"model": self.name, "friction": self.geometry.friction, **attrs.asdict(self.physics)}
