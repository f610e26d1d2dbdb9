"""The table-top world: a table, the arm at its edge, oranges and a bowl, a front camera."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..primitives import Box, Cylinder
from ..world import World
from .arm import SimArm, look_at

TABLE_HEIGHT = 0.4
TABLE_SIZE = (0.8, 0.7)
ARM_BASE = (-0.3, 0.0)  # on the table, near its -x edge, facing +x
ORANGE_RADIUS = 0.033
# Within the arm's reach (0.16-0.22 m from its base, gripper pointing down, joint limits kept).
ORANGES = ((-0.11, 0.03), (-0.12, -0.07), (-0.14, -0.15))  # table-top (x, y)
BOWL_CENTER = (-0.15, 0.16)
BOWL_RADIUS = 0.08
BOWL_HEIGHT = 0.045
FRONT_CAMERA_EYE = (0.45, 0.0, TABLE_HEIGHT + 0.35)
FRONT_CAMERA_TARGET = (-0.15, 0.0, TABLE_HEIGHT)


def bowl_shapes(center: tuple[float, float], radius: float = BOWL_RADIUS, height: float = BOWL_HEIGHT,
                base: float = TABLE_HEIGHT) -> list[Any]:
    """A bowl as static shapes: a flat bottom and a ring of 16 wall segments, standing on ``base``.

    Static shapes stand on z = 0, so the bowl's pieces are as tall as the table plus the bowl:
    the table hides their lower part."""
    color = (0.2, 0.35, 0.75, 1.0)
    parts: list[Any] = [Cylinder(center, radius, base + 0.006, color=color)]
    n = 16
    seg = 2 * radius * math.tan(math.pi / n) + 0.004
    for k in range(n):
        a = 2 * math.pi * k / n
        cx, cy = center[0] + radius * math.cos(a), center[1] + radius * math.sin(a)
        parts.append(Box((cx, cy), (0.008, seg), base + height, yaw=a, color=color))
    return parts


class TabletopWorld(World):
    """A :class:`World` with the table-top scene's parts, set by :func:`tabletop_world`."""

    arm: SimArm
    oranges: list[int]  # pybullet body ids
    front_camera_pose: tuple[np.ndarray, np.ndarray]  # (position, optical rotation), see look_at


def tabletop_world(**world_kwargs: Any) -> TabletopWorld:
    """A dynamic world with the arm on a table, three oranges and a bowl (see module constants)."""
    world = TabletopWorld(name="tabletop", **world_kwargs)
    world.enable_dynamics()
    world.add(Box((0.0, 0.0), TABLE_SIZE, TABLE_HEIGHT, color=(0.6, 0.45, 0.3, 1.0)))
    world.add(bowl_shapes(BOWL_CENTER))
    world.step()  # bake the static shapes before the dynamic bodies drop onto them
    world.arm = SimArm(world, _arm_config())
    world.oranges = [_orange(world, xy) for xy in ORANGES]
    world.arm.graspable.update(world.oranges)
    world.front_camera_pose = look_at(FRONT_CAMERA_EYE, FRONT_CAMERA_TARGET)
    world.spawn = None
    world.run_for(0.5)  # let the oranges settle and the arm reach its ready pose
    return world


def _arm_config() -> Any:
    from .arm import ArmConfig

    return ArmConfig(base_xyz=(ARM_BASE[0], ARM_BASE[1], TABLE_HEIGHT))


def _orange(world: World, xy: tuple[float, float]) -> int:
    from .. import _deps

    pb = _deps.pybullet()
    c = world.client
    col = c.createCollisionShape(pb.GEOM_SPHERE, radius=ORANGE_RADIUS)
    vis = c.createVisualShape(pb.GEOM_SPHERE, radius=ORANGE_RADIUS, rgbaColor=[1.0, 0.55, 0.05, 1.0])
    body = c.createMultiBody(baseMass=0.12, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis,
                             basePosition=[xy[0], xy[1], TABLE_HEIGHT + ORANGE_RADIUS + 0.002])
    c.changeDynamics(body, -1, lateralFriction=1.2, rollingFriction=0.002, spinningFriction=0.002)
    world._body_names[body] = "orange"
    return int(body)


def orange_positions(world: TabletopWorld) -> np.ndarray:
    return np.array([world.client.getBasePositionAndOrientation(b)[0] for b in world.oranges])
