"""The simulated robot of a navigation ``RobotConfig``: the robot the planner plans for.

``launcher.robot = RobotConfig(...)`` reaches the Simulator too (its config has ``robot``), so
the simulated body, drive and limits are the ones navigation assumes: a BOX geometry becomes
a box body, every other geometry a cylinder of its footprint radius; speed limits are the
control limits and the acceleration limit is the larger of acceleration and deceleration
(the base can brake as hard as the controller may ask).
"""
from __future__ import annotations

from typing import Any

from ..robots import RobotSpec, robot_spec


def spec_from_robot_config(rc: Any, name: str = "robot") -> RobotSpec:
    from emos.actors.nav.robot import RobotGeometry, RobotType

    drive = {RobotType.DIFFERENTIAL_DRIVE: "differential", RobotType.ACKERMANN: "ackermann",
             RobotType.OMNI: "omni"}[rc.model_type]
    height = float(rc.height)
    if rc.geometry_type is RobotGeometry.Type.BOX:
        length, width, radius = float(rc.geometry_params[0]), float(rc.geometry_params[1]), 0.0
    else:
        radius = float(rc.radius)
        length = width = 2 * radius
    vx, vy, w = rc.ctrl_vx_limits, rc.ctrl_vy_limits, rc.ctrl_omega_limits
    omni = drive == "omni"
    return RobotSpec(
        name=name, drive=drive, length=length, width=width, height=height, radius=radius,
        max_vx=vx.max_vel, max_acc_x=max(vx.max_acc, vx.max_decel),
        max_omega=w.max_vel if w.max_vel > 0 else 1.0, max_acc_omega=max(w.max_acc, w.max_decel),
        max_vy=vy.max_vel if omni else 0.0, max_acc_y=max(vy.max_acc, vy.max_decel) if omni else 0.0,
        wheelbase=rc.wheel_base if drive == "ackermann" else 0.0,
        max_steer=w.max_steer if drive == "ackermann" else 0.0,
        lidar_height=max(height, 0.05) + 0.02,  # a lidar on top of the body, above its own collision shape
    )


def resolve_robot(value: Any) -> RobotSpec:
    """A preset name or a navigation ``RobotConfig`` as the simulator's ``RobotSpec``."""
    if isinstance(value, str):
        return robot_spec(value)
    return spec_from_robot_config(value)
