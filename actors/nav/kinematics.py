"""Kinematics of the three motion models, vectorized over many command samples.

Commands are body-frame velocities ``(vx, vy, omega)``; poses are ``(x, y, yaw)``. Every
function broadcasts over leading axes, so a DWA step rolls out N samples over a horizon with
one call and no Python loop over samples.
"""
from __future__ import annotations

import math

import numpy as np

from emos.geometry import arc_steps, integrate_pose, wrap_angle

from .robot import RobotConfig, RobotType

__all__ = [
    "wrap_angle",
    "feasible_commands",
    "dynamic_window",
    "limit_command_change",
    "integrate",
    "rollout",
    "to_robot_frame",
    "to_world_frame",
    "ramp_commands",
    "integrate_sequence",
]


def feasible_commands(robot: RobotConfig, commands: np.ndarray) -> np.ndarray:
    """Project commands (..., 3) onto what the motion model can execute within velocity limits.

    Non-omni robots cannot move sideways; Ackermann robots cannot turn tighter than their
    steering angle allows, so ``|omega| <= |vx| * tan(max_steer) / wheel_base``.
    """
    cmd = np.array(commands, dtype=np.float64, copy=True)
    if cmd.shape[-1] != 3:
        raise ValueError(f"commands: expected shape (..., 3) as (vx, vy, omega), got {cmd.shape}")
    vx_max = robot.ctrl_vx_limits.max_vel
    om_max = robot.ctrl_omega_limits.max_vel
    np.clip(cmd[..., 0], -vx_max, vx_max, out=cmd[..., 0])
    if robot.model_type is RobotType.OMNI:
        vy_max = robot.ctrl_vy_limits.max_vel
        np.clip(cmd[..., 1], -vy_max, vy_max, out=cmd[..., 1])
    else:
        cmd[..., 1] = 0.0
    if robot.model_type is RobotType.ACKERMANN:
        om_lim = np.minimum(np.abs(cmd[..., 0]) * robot.max_curvature, om_max)
        cmd[..., 2] = np.clip(cmd[..., 2], -om_lim, om_lim)
    else:
        np.clip(cmd[..., 2], -om_max, om_max, out=cmd[..., 2])
    return cmd


def _axis_window(v: float, max_vel: float, acc: float, dec: float, dt: float) -> tuple[float, float]:
    """Reachable [lo, hi] for one axis in ``dt``.

    Speeding up (growing |v|) is bounded by ``acc``, slowing down by ``dec``; once the axis
    has crossed zero it is speeding up again in the other direction.
    """
    if v >= 0.0:
        hi = v + acc * dt
        lo = v - dec * dt
        if lo < 0.0:  # braked through zero: the rest of dt accelerates backwards
            lo = -acc * (dt - v / dec)
    else:
        lo = v - acc * dt
        hi = v + dec * dt
        if hi > 0.0:
            hi = acc * (dt + v / dec)
    return max(lo, -max_vel), min(hi, max_vel)


def dynamic_window(robot: RobotConfig, velocity: np.ndarray, dt: float) -> np.ndarray:
    """Reachable velocity box ``[[vx_lo, vx_hi], [vy_lo, vy_hi], [om_lo, om_hi]]`` after ``dt``."""
    if not (dt > 0.0 and math.isfinite(dt)):
        raise ValueError(f"dt: expected a finite time step > 0 s, got {dt!r}")
    v = np.asarray(velocity, dtype=np.float64).reshape(3)
    lx, ly, lw = robot.ctrl_vx_limits, robot.ctrl_vy_limits, robot.ctrl_omega_limits
    win = np.zeros((3, 2))
    win[0] = _axis_window(float(v[0]), lx.max_vel, lx.max_acc, lx.max_decel, dt)
    if robot.model_type is RobotType.OMNI:
        win[1] = _axis_window(float(v[1]), ly.max_vel, ly.max_acc, ly.max_decel, dt)
    win[2] = _axis_window(float(v[2]), lw.max_vel, lw.max_acc, lw.max_decel, dt)
    # A robot that starts outside its limits (e.g. limits just changed) must still get a
    # non-empty window: collapse to the nearest reachable value.
    bad = win[:, 0] > win[:, 1]
    win[bad] = np.clip(v[bad], win[bad, 1], win[bad, 0])[:, None]
    return win


def limit_command_change(
    robot: RobotConfig, previous: np.ndarray, target: np.ndarray, dt: float
) -> np.ndarray:
    """Move from ``previous`` towards ``target`` as far as the acc/decel limits allow in ``dt``."""
    win = dynamic_window(robot, previous, dt)
    tgt = feasible_commands(robot, target)
    return feasible_commands(robot, np.clip(tgt, win[:, 0], win[:, 1]))


def integrate(pose: np.ndarray, commands: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """Exact pose after applying constant body velocities for ``dt`` (broadcasts): see
    :func:`emos.geometry.integrate_pose`."""
    return integrate_pose(pose, commands, dt)


def rollout(pose: np.ndarray, commands: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """Constant-velocity rollouts: ``commands`` (N, 3) -> poses (N, steps + 1, 3).

    Entry 0 is the start pose. All samples and all steps are computed at once in closed form.
    """
    if steps < 1:
        raise ValueError(f"steps: expected >= 1, got {steps}")
    cmd = np.asarray(commands, dtype=np.float64).reshape(-1, 3)
    start = np.asarray(pose, dtype=np.float64).reshape(3)
    t = (np.arange(steps + 1, dtype=np.float64) * dt)[None, :]  # (1, S+1)
    return integrate(start[None, None, :], cmd[:, None, :], t)


def to_robot_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World 2D points (..., 2) into the frame of ``pose`` (x, y, yaw)."""
    p = np.asarray(points, dtype=np.float64)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx = p[..., 0] - pose[0]
    dy = p[..., 1] - pose[1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def to_world_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Robot-frame 2D points (..., 2) into the world, given the robot ``pose``."""
    p = np.asarray(points, dtype=np.float64)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.stack(
        [pose[0] + c * p[..., 0] - s * p[..., 1], pose[1] + s * p[..., 0] + c * p[..., 1]], axis=-1
    )


def ramp_commands(robot: RobotConfig, velocity: np.ndarray, targets: np.ndarray, dt: float,
                  steps: int) -> np.ndarray:
    """Commands (N, steps, 3) moving from ``velocity`` towards each target (N, 3) per step.

    Each step changes each axis by at most ``max_acc * dt`` while |v| grows and by at most
    ``max_decel * dt`` while it shrinks. The loop runs over steps (a handful), never samples.
    """
    tgt = feasible_commands(robot, np.asarray(targets, dtype=np.float64).reshape(-1, 3))
    lim = (robot.ctrl_vx_limits, robot.ctrl_vy_limits, robot.ctrl_omega_limits)
    acc = np.array([axis.max_acc for axis in lim]) * dt
    dec = np.array([axis.max_decel for axis in lim]) * dt
    v = np.broadcast_to(np.asarray(velocity, dtype=np.float64).reshape(1, 3), tgt.shape).copy()
    out = np.empty((tgt.shape[0], steps, 3))
    for k in range(steps):
        delta = tgt - v
        # Moving away from zero (same sign as v, or from rest) is acceleration; else braking.
        speeding = (v * delta > 0) | (v == 0)
        step = np.where(speeding, acc, dec)
        v = v + np.minimum(np.maximum(delta, -step), step)  # np.clip's wrapper costs more than the step
        out[:, k] = v
    return feasible_commands(robot, out)


def integrate_sequence(pose: np.ndarray, commands: np.ndarray, dt: float) -> np.ndarray:
    """Poses (N, K + 1, 3) from applying command sequences (N, K, 3) for ``dt`` each."""
    cmds = np.asarray(commands, dtype=np.float64)
    if cmds.ndim == 2:
        cmds = cmds[None]
    n, k, _ = cmds.shape
    start = np.asarray(pose, dtype=np.float64).reshape(3)
    out = np.empty((n, k + 1, 3))
    out[:, 0] = start
    # All steps at once: the heading at each step's start is the running sum of the turns, and
    # each step's arc, turned into the world by that heading, adds to the running position.
    dx_b, dy_b, dth = arc_steps(cmds, dt)
    heading = start[2] + np.cumsum(dth, axis=1)
    before = np.concatenate([np.full((n, 1), start[2]), heading[:, :-1]], axis=1)
    c, s = np.cos(before), np.sin(before)
    out[:, 1:, 0] = start[0] + np.cumsum(c * dx_b - s * dy_b, axis=1)
    out[:, 1:, 1] = start[1] + np.cumsum(s * dx_b + c * dy_b, axis=1)
    out[:, 1:, 2] = wrap_angle(heading)
    return out
