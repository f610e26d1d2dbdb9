"""Shared pieces of the controllers: ids, result type, config validators, common config."""
from __future__ import annotations

import enum
import math
from typing import Any

import attrs
import numpy as np

from emos.config.validators import in_range  # the nav configs import it from here

__all__ = ["ControllersID", "ControlResult", "ControlStatus", "in_range", "FollowerConfig", "setters", "robot_state"]

# Validate on every assignment, not only at construction.
setters = attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate)


class ControllersID(str, enum.Enum):
    """Controller ids (their value is the name used in configs: ``algorithm="DWA"``)."""

    STANLEY = "Stanley"
    DWA = "DWA"
    DVZ = "DVZ"
    PURE_PURSUIT = "PurePursuit"
    VISION_IMG = "VisionRGBFollower"
    VISION_DEPTH = "VisionRGBDFollower"
    ARC_SAMPLER = "ArcSampler"  # sampled constant-velocity arcs scored by cost-to-go (BARN's local planner)
    MPPI = "MPPI"  # Model Predictive Path Integral, Nav2's parameters and critics
    REGULATED_PURE_PURSUIT = "RegulatedPurePursuit"  # Nav2's RPP: curvature- and proximity-regulated speed

    @classmethod
    def from_any(cls, value: ControllersID | str) -> ControllersID:
        if isinstance(value, cls):
            return value
        for member in cls:
            if value in (member.value, member.name):
                return member
        raise ValueError(f"controller id: expected one of {[m.value for m in cls]}, got {value!r}")


class ControlStatus(str, enum.Enum):
    RUNNING = "running"
    GOAL_REACHED = "goal_reached"
    ROTATING = "rotating"  # rotate-then-move: aligning before driving
    AVOIDING = "avoiding"  # nominal command blocked, a detour command was chosen
    BLOCKED = "blocked"  # no collision-free command: braking
    SEARCHING = "searching"  # vision: target lost, searching
    WAITING = "waiting"  # vision: target lost, pausing before searching
    LOST = "lost"  # vision: target lost and search timed out / disabled
    NO_PATH = "no_path"


@attrs.define
class ControlResult:
    """Velocity commands for the next steps and the local plan they are expected to follow.

    ``commands`` (K, 3) body-frame (vx, vy, omega), one per ``control_time_step``;
    ``local_plan`` (K', 3) world poses starting at the current pose.
    """

    commands: np.ndarray
    local_plan: np.ndarray
    status: ControlStatus = ControlStatus.RUNNING
    info: dict[str, Any] = attrs.field(factory=dict)

    @property
    def command(self) -> np.ndarray:
        """The command to apply now."""
        return self.commands[0]

    @classmethod
    def stop(cls, pose: np.ndarray, status: ControlStatus, steps: int = 1, **info: Any) -> ControlResult:
        return cls(np.zeros((max(steps, 1), 3)), np.asarray(pose, dtype=np.float64).reshape(1, 3), status, info)


def robot_state(pose: Any, velocity: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate the robot state: pose (x, y, yaw) and body velocity (vx, vy, omega), finite."""
    out = []
    for name, value in (("pose", pose), ("velocity", velocity)):
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
        if arr.size != 3 or not np.all(np.isfinite(arr)):
            expected = "(x, y, yaw)" if name == "pose" else "(vx, vy, omega)"
            raise ValueError(f"{name}: expected 3 finite numbers {expected}, got {value!r}")
        out.append(arr)
    return out[0], out[1]


def _field(default: Any, lo: float, hi: float, conv: type = float) -> Any:
    return attrs.field(default=default, converter=conv, validator=in_range(lo, hi), on_setattr=setters)


@attrs.define
class FollowerConfig:
    """Parameters common to the path followers.

    ``control_time_step`` is the command period (s). ``goal_dist_tolerance`` (m) ends the
    tracking; ``path_resolution`` (m) is the spacing the reference path is resampled to;
    ``rotate_in_place_angle`` (rad) is the heading error above which non-Ackermann robots
    rotate in place before moving (the rotate-then-move policy); ``safety_margin`` (m) is the clearance a chosen
    trajectory must keep from obstacles.
    """

    control_time_step: float = _field(0.1, 1e-4, 1e6)
    goal_dist_tolerance: float = _field(0.1, 1e-3, 1e3)
    path_resolution: float = _field(0.02, 1e-3, 1.0)
    rotate_in_place_angle: float = _field(math.pi / 3, 0.0, math.pi)
    safety_margin: float = _field(0.05, 0.0, 10.0)


field = _field
