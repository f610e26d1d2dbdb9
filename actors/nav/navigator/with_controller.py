"""The mapless navigator's global layer with one of the path followers as local controller.

The global layer is the mapless navigator's (lidar obstacle memory, Dijkstra cost-to-go, plan,
stuck recovery); each control step hands the plan and the nearby obstacle points to one of
the navigation core's path followers (DWA, PurePursuit, Stanley, DVZ) and applies its command.
"""
from __future__ import annotations

import math

import numpy as np

from .interface import NavTask, Observation
from .mapless import GridNavigator

# navigator name -> class names in emos.actors.nav.controllers (controller, config).
NAVCORE_CONTROLLERS = {
    "navcore-dwa": ("DWA", "DWAConfig"),
    "navcore-purepursuit": ("PurePursuit", "PurePursuitConfig"),
    "navcore-stanley": ("Stanley", "StanleyConfig"),
    "navcore-dvz": ("DVZ", "DVZConfig"),
    "mppi": ("MPPI", "MPPIConfig"),
    "rpp": ("RegulatedPurePursuit", "RegulatedPurePursuitConfig"),
}


class NavCoreNavigator:
    def __init__(self, name: str) -> None:
        if name not in NAVCORE_CONTROLLERS:
            raise ValueError(f"unknown local controller {name!r}; expected one of {sorted(NAVCORE_CONTROLLERS)}")
        self.name = name
        self._global = GridNavigator()
        self.plan: np.ndarray | None = None
        self._tracked: np.ndarray | None = None

    def reset(self, task: NavTask) -> None:
        from .. import controllers

        robot = task.robot
        cls_name, cfg_name = NAVCORE_CONTROLLERS[self.name]
        config = getattr(controllers, cfg_name)(control_time_step=1.0 / task.control_rate_hz,
                                                 goal_dist_tolerance=min(0.5, task.goal_radius))
        self.controller = getattr(controllers, cls_name)(robot, config)
        self._global.reset(task)
        self.task = task
        self.plan = None
        self._tracked = None

    def step(self, obs: Observation) -> tuple[float, float, float]:
        obs = self._global.localized(obs)
        self._global.update(obs)
        plan = self._global.plan
        self.plan = plan
        if plan is None or len(plan) < 2:
            return (0.0, 0.0, 0.0)
        if plan is not self._tracked:
            # Follow the plan to the goal itself (the plan ends at the goal's cell centre).
            self.controller.set_path(np.vstack([plan, np.asarray(self.task.goal)[None]]))
            self._tracked = plan
        x, y, yaw = obs.pose
        pts = self._global.grid.points_near((x, y), 3.0)
        c, s = math.cos(yaw), math.sin(yaw)
        rel = pts - (x, y)
        local = np.c_[c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]  # robot frame
        result = self.controller.compute(np.asarray(obs.pose, dtype=float), np.asarray(obs.twist, dtype=float), local)
        vx, vy, w = (float(v) for v in result.command)
        return (vx, vy, w)
