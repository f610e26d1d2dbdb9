"""``SimArm``: a position-controlled arm loaded from a URDF, with joint states and a wrist camera.

The shipped model (``emos.actors.sim.data/so101_like.urdf``) has the SO-101's joint names
``Rotation, Pitch, Elbow, Wrist_Pitch, Wrist_Roll, Jaw`` (radians; all zero = pointing up,
jaw closed; ``Jaw`` > 0 opens), so VLA recipes written for the SO-101 map their dataset keys
(``shoulder_pan.pos`` -> ``Rotation`` ...) onto it unchanged. Unlike the mobile bases, the arm
is simulated with pybullet's dynamics: joint motors track position targets with limited
effort, and grasped objects are held by contact friction.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from .. import _deps
from ..data import DATA_DIR
from ..sensors.base import Sensor, check_rate
from ..sensors.camera import Camera, CameraConfig

if TYPE_CHECKING:
    from ..world import World

ARM_URDF = DATA_DIR / "so101_like.urdf"
ARM_JOINTS = ("Rotation", "Pitch", "Elbow", "Wrist_Pitch", "Wrist_Roll", "Jaw")
# Where the joints start: gripper pointing down and forward, about 5 cm above the table, jaw open.
READY_POSE = {"Rotation": 0.0, "Pitch": 0.0, "Elbow": 1.2, "Wrist_Pitch": 1.5, "Wrist_Roll": 0.0, "Jaw": 0.4}


@attrs.define(frozen=True)
class ArmConfig:
    urdf: str = attrs.field(default=str(ARM_URDF), converter=str)
    base_xyz: tuple[float, float, float] = attrs.field(default=(0.0, 0.0, 0.0), converter=lambda v: tuple(float(x) for x in v))
    base_yaw: float = attrs.field(default=0.0, converter=float)
    position_gain: float = attrs.field(default=0.3, converter=float)
    max_velocity: float = attrs.field(default=2.0, converter=float)  # rad/s per joint

    def __attrs_post_init__(self) -> None:
        if not Path(self.urdf).is_file():
            raise ValueError(f"ArmConfig.urdf: {self.urdf!r} does not exist")
        if not (0 < self.position_gain <= 1 and self.max_velocity > 0):
            raise ValueError("ArmConfig: position_gain must be in (0, 1] and max_velocity > 0")


class SimArm:
    """An arm fixed to the world. ``command(names, positions)`` sets joint targets."""

    def __init__(self, world: World, config: ArmConfig | None = None, initial: dict[str, float] | None = None) -> None:
        self.world, self.config = world, config or ArmConfig()
        c = world.client
        yaw = self.config.base_yaw
        with _deps.c_stdout_silenced():
            self.body_id = c.loadURDF(self.config.urdf, list(self.config.base_xyz), [0, 0, math.sin(yaw / 2), math.cos(yaw / 2)],
                                      useFixedBase=True, flags=_deps.pybullet().URDF_USE_SELF_COLLISION_EXCLUDE_PARENT)
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {}
        self.limits: dict[str, tuple[float, float]] = {}
        for j in range(c.getNumJoints(self.body_id)):
            info = c.getJointInfo(self.body_id, j)
            name, kind, link = info[1].decode(), info[2], info[12].decode()
            self.link_index[link] = j
            if kind == _deps.pybullet().JOINT_REVOLUTE:
                self.joint_index[name] = j
                self.limits[name] = (float(info[8]), float(info[9]))
        self.names = [n for n in ARM_JOINTS if n in self.joint_index] + [n for n in self.joint_index if n not in ARM_JOINTS]
        self._efforts = {n: float(c.getJointInfo(self.body_id, self.joint_index[n])[10]) for n in self.names}
        self.targets = {n: 0.0 for n in self.names}
        start = dict(READY_POSE if initial is None else initial)
        for name, value in start.items():
            self._check_name(name)
            c.resetJointState(self.body_id, self.joint_index[name], self._clip(name, value))
        for link in ("jaw", "fixed_finger"):  # rubber finger pads: objects are held by friction
            if link in self.link_index:
                c.changeDynamics(self.body_id, self.link_index[link], lateralFriction=2.0, spinningFriction=0.01,
                                 rollingFriction=0.001, frictionAnchor=True)
        self.command(list(start), list(start.values()))
        world._body_names[self.body_id] = "arm"
        self.graspable: set[int] = set()  # bodies the jaw may hold (see update_grasp)
        self.held: int | None = None
        self._grasp: int | None = None  # the constraint holding ``held``
        world.tick_hooks.append(self.update_grasp)

    def _check_name(self, name: str) -> None:
        if name not in self.joint_index:
            raise ValueError(f"arm has no joint {name!r}; its joints are {', '.join(self.names)}")

    def _clip(self, name: str, value: float) -> float:
        lo, hi = self.limits[name]
        return float(np.clip(value, lo, hi))

    def command(self, names: Sequence[str], positions: Sequence[float]) -> None:
        """Position targets by joint name (clipped to the joint limits); other joints keep theirs."""
        if len(names) != len(positions):
            raise ValueError(f"arm command has {len(names)} names but {len(positions)} positions")
        values = np.asarray(positions, dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"arm command positions must be finite, got {values.tolist()!r}")
        for name in names:
            self._check_name(name)
        for name, value in zip(names, values):
            self.targets[name] = self._clip(name, float(value))
        pb = _deps.pybullet()
        idx = [self.joint_index[n] for n in self.names]
        self.world.client.setJointMotorControlArray(
            self.body_id, idx, pb.POSITION_CONTROL, targetPositions=[self.targets[n] for n in self.names],
            forces=[self._efforts[n] for n in self.names], positionGains=[self.config.position_gain] * len(idx))
        for j in idx:  # cap joint speed so a far target is approached smoothly
            self.world.client.changeDynamics(self.body_id, j, maxJointVelocity=self.config.max_velocity)

    def update_grasp(self, stamp: float = 0.0) -> None:
        """Hold a graspable body while the jaw closes on it; let go when the jaw opens.

        A body squeezed between the jaw and the fixed finger (touching both) while the jaw is
        commanded to close is fixed to the gripper where it is; commanding the jaw to open
        (a target wider than where it is) releases it. Box fingers pinching a sphere slip in
        a rigid-body engine however they are tuned, so the pinch is made to hold, as simulator
        grasp plug-ins do; the jaw still has to reach and close on the object.
        """
        c, pb = self.world.client, _deps.pybullet()
        jaw_now = c.getJointState(self.body_id, self.joint_index["Jaw"])[0]
        if self.held is not None:
            if self.targets["Jaw"] > jaw_now + 0.05:
                c.removeConstraint(self._grasp)
                self.held = self._grasp = None
            return
        if self.targets["Jaw"] >= jaw_now - 0.02:  # not closing
            return
        jaw, finger = self.link_index["jaw"], self.link_index["fixed_finger"]
        for body in self.graspable:
            touching = {p[3] for p in c.getContactPoints(bodyA=self.body_id, bodyB=body)}
            if jaw in touching and finger in touching:
                gripper = self.link_index["gripper"]
                g_pos, g_orn = c.getLinkState(self.body_id, gripper)[4:6]
                b_pos, b_orn = c.getBasePositionAndOrientation(body)
                inv_pos, inv_orn = c.invertTransform(g_pos, g_orn)
                rel_pos, rel_orn = c.multiplyTransforms(inv_pos, inv_orn, b_pos, b_orn)
                self._grasp = c.createConstraint(self.body_id, gripper, body, -1, pb.JOINT_FIXED, [0, 0, 0],
                                                 rel_pos, [0, 0, 0], rel_orn)
                c.changeConstraint(self._grasp, maxForce=50.0)
                self.held = body
                return

    def joint_state(self) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
        """(names, positions, velocities, efforts)."""
        states = self.world.client.getJointStates(self.body_id, [self.joint_index[n] for n in self.names])
        pos = np.array([s[0] for s in states])
        vel = np.array([s[1] for s in states])
        eff = np.array([s[3] for s in states])
        return list(self.names), pos, vel, eff

    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of ``link``."""
        state = self.world.client.getLinkState(self.body_id, self.link_index[link], computeForwardKinematics=True)
        position = np.asarray(state[4], dtype=float)
        rotation = np.asarray(self.world.client.getMatrixFromQuaternion(state[5]), dtype=float).reshape(3, 3)
        return position, rotation


@attrs.define(frozen=True, eq=False)
class JointStateReading:
    stamp: float
    names: list[str]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class JointStateSensor(Sensor):
    """The arm's joint states at ``rate_hz``."""

    def __init__(self, arm: SimArm, rate_hz: float = 30.0, name: str = "joint_states") -> None:
        super().__init__(None, name)  # type: ignore[arg-type]  # rides on no mobile robot
        self.arm, self.rate_hz = arm, check_rate("JointStateSensor", rate_hz)

    def read(self, stamp: float) -> JointStateReading:
        names, pos, vel, eff = self.arm.joint_state()
        return JointStateReading(stamp, names, pos, vel, eff)


class PosedCamera(Camera):
    """A camera whose pose comes from a callable (a fixed scene camera, an arm's wrist)."""

    def __init__(self, pose: Any, config: CameraConfig | None = None, name: str = "camera") -> None:
        super().__init__(None, config, name)  # type: ignore[arg-type]
        self._pose_fn = pose

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self._pose_fn()


def look_at(eye: Sequence[float], target: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose (position, optical rotation: columns x right, y down, z forward) looking at a point."""
    position, aim = np.asarray(eye, float), np.asarray(target, float)
    forward = (aim - position) / np.linalg.norm(aim - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return position, np.c_[right, down, forward]


def wrist_camera_pose(arm: SimArm) -> tuple[np.ndarray, np.ndarray]:
    """The wrist camera looks along the gripper (its +z) with the jaw (gripper +x) at the image's
    bottom, as a camera on the SO-101's wrist sees the jaw."""
    position, rot = arm.link_pose("wrist_camera_link")
    forward, down = rot[:, 2], rot[:, 0]
    right = np.cross(down, forward)
    return position, np.c_[right, down, forward]
