"""VisionRGBFollower: keep a 2D bounding box centred (rotation) and at its first size (speed).

No depth: the box size when tracking starts is the distance to keep. Errors within
``tolerance`` give no command on that axis; a non-zero linear command is at least ``min_vel``.
A lost target triggers :class:`TargetSearch`.
"""
from __future__ import annotations

import math

import attrs
import numpy as np

from ..kinematics import integrate_sequence, ramp_commands
from ..robot import RobotConfig
from .base import ControlResult, ControlStatus, field, robot_state, setters
from .vision_common import BoundingBox, TargetSearch

__all__ = ["VisionRGBFollowerConfig", "VisionRGBFollower"]


@attrs.define
class VisionRGBFollowerConfig:
    """``control_horizon`` and ``target_search_pause`` are counted in control steps."""

    control_time_step: float = field(0.1, 1e-4, 1e6)
    control_horizon: int = field(2, 1, 1000, int)
    rotation_gain: float = field(1.0, 1e-3, 1e2)
    speed_gain: float = field(0.7, 1e-3, 1e2)
    tolerance: float = field(0.1, 0.0, 1.0)
    target_search_timeout: float = field(30.0, 0.0, 1e6)
    target_search_pause: float = field(2, 0, 1e6)
    enable_search: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool), on_setattr=setters)
    min_vel: float = field(0.1, 0.0, 1e2)


class VisionRGBFollower:
    def __init__(self, robot: RobotConfig, config: VisionRGBFollowerConfig | None = None) -> None:
        self.robot = robot
        self.config = config or VisionRGBFollowerConfig()
        cfg = self.config
        self.search = TargetSearch(robot, cfg.control_time_step, cfg.target_search_pause,
                                   cfg.target_search_timeout, cfg.enable_search)
        self.reference_size: float | None = None

    def reset(self) -> None:
        """Forget the reference size: the next detection defines the distance to keep."""
        self.reference_size = None

    def compute(self, target: BoundingBox | None, velocity: np.ndarray | None = None,
                pose: np.ndarray | None = None) -> ControlResult:
        """One step towards ``target``; ``velocity`` and ``pose`` default to zero (robot at rest at the origin)."""
        cfg = self.config
        robot = self.robot
        pose, velocity = robot_state(np.zeros(3) if pose is None else pose,
                                     np.zeros(3) if velocity is None else velocity)
        if target is None:
            cmd, status = self.search.step()
        else:
            if self.reference_size is None:
                self.reference_size = target.relative_size
            ex = target.horizontal_error
            self.search.seen(-ex)
            w = 0.0
            if abs(ex) > cfg.tolerance:
                w = -cfg.rotation_gain * ex * robot.ctrl_omega_limits.max_vel
            # Positive when the box is smaller than at the start: the target moved away.
            es = (self.reference_size - target.relative_size) / self.reference_size
            v = 0.0
            if abs(es) > cfg.tolerance:
                v = cfg.speed_gain * es * robot.ctrl_vx_limits.max_vel
                v = math.copysign(max(abs(v), cfg.min_vel), v)
            if robot.model_type.name == "ACKERMANN" and w != 0.0 and abs(v) < cfg.min_vel:
                # A car turns only while rolling: creep forward to be able to re-centre.
                v = cfg.min_vel
            cmd, status = np.array([v, 0.0, w]), ControlStatus.RUNNING
        cmds = ramp_commands(robot, velocity, cmd[None], cfg.control_time_step, cfg.control_horizon)[0]
        plan = integrate_sequence(pose, cmds, cfg.control_time_step)[0]
        return ControlResult(cmds, plan, status, {"reference_size": self.reference_size})
