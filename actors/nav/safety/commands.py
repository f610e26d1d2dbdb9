"""Command limiting and smoothing: the last filter before velocities reach the motors."""
from __future__ import annotations

import math

import attrs
import numpy as np

from ..controllers.base import in_range, setters
from ..kinematics import feasible_commands, limit_command_change
from ..robot import RobotConfig

__all__ = ["CommandFilterConfig", "CommandFilter", "interpolate_commands"]


@attrs.define
class CommandFilterConfig:
    """``smoothing_time_constant`` (s) of the first-order low-pass; 0 disables smoothing."""

    control_time_step: float = attrs.field(default=0.1, converter=float, validator=in_range(1e-4, 1e3), on_setattr=setters)
    smooth_commands: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool), on_setattr=setters)
    smoothing_time_constant: float = attrs.field(default=0.2, converter=float, validator=in_range(0.0, 1e3), on_setattr=setters)


class CommandFilter:
    """Clamp to velocity limits, limit acceleration and deceleration separately, smooth.

    Stateful: remembers the last command sent. Smoothing never delays braking: when the new
    command slows an axis down, the deceleration limit alone applies.
    """

    def __init__(self, robot: RobotConfig, config: CommandFilterConfig | None = None) -> None:
        self.robot = robot
        self.config = config or CommandFilterConfig()
        self.last = np.zeros(3)

    def reset(self, velocity: np.ndarray | None = None) -> None:
        self.last = np.zeros(3) if velocity is None else np.asarray(velocity, dtype=np.float64).copy()

    def __call__(self, command: np.ndarray) -> np.ndarray:
        cfg = self.config
        cmd = np.asarray(command, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(cmd)):
            raise ValueError(f"command: expected finite (vx, vy, omega), got {cmd.tolist()}")
        target = feasible_commands(self.robot, cmd)
        if cfg.smooth_commands and cfg.smoothing_time_constant > 0:
            alpha = cfg.control_time_step / (cfg.smoothing_time_constant + cfg.control_time_step)
            smoothed = self.last + alpha * (target - self.last)
            slowing = np.abs(target) < np.abs(self.last)
            target = np.where(slowing, target, smoothed)
        out = limit_command_change(self.robot, self.last, target, cfg.control_time_step)
        self.last = out
        return out


def interpolate_commands(commands: np.ndarray, dt_in: float, dt_out: float) -> np.ndarray:
    """Resample a command sequence (K, 3) given every ``dt_in`` s to every ``dt_out`` s.

    Commands are piecewise constant over their step (zero-order hold), as a controller
    publishing a multi-step command intends.
    """
    cmds = np.asarray(commands, dtype=np.float64).reshape(-1, 3)
    if dt_in <= 0 or dt_out <= 0:
        raise ValueError(f"dt_in, dt_out: expected > 0 s, got {dt_in}, {dt_out}")
    n_out = max(1, int(math.floor(cmds.shape[0] * dt_in / dt_out + 1e-9)))
    idx = np.minimum((np.arange(n_out) * dt_out / dt_in + 1e-9).astype(np.int64), cmds.shape[0] - 1)
    return cmds[idx]
