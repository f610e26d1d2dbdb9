"""A tiny kinematic 2D simulator for closed-loop controller tests.

The robot executes each command exactly (the controllers already respect acceleration
limits); circular obstacles are seen through a simulated LaserScan with exact ray-circle
intersections. Clearance is measured against dense obstacle boundary points with the robot's
real footprint.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from emos.actors.nav.controllers.clearance import pose_clearance
from emos.actors.nav.controllers.sensors import LaserScan2D
from emos.actors.nav.kinematics import integrate
from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig


def make_robot(model: str, geometry: str = "CYLINDER", params=(0.15, 0.3)) -> RobotConfig:
    return RobotConfig(
        model_type=model, geometry_type=geometry, geometry_params=np.array(params),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.0, max_decel=2.0),
        ctrl_vy_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.0, max_decel=2.0),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0, max_steer=math.pi / 3),
    )


def straight_path(length: float = 4.0) -> np.ndarray:
    x = np.linspace(0.0, length, 81)
    return np.stack([x, np.zeros_like(x)], axis=1)


def u_turn_path(leg: float = 2.0, radius: float = 1.0) -> np.ndarray:
    a = np.stack([np.linspace(0, leg, 41), np.zeros(41)], 1)
    th = np.linspace(-math.pi / 2, math.pi / 2, 63)[1:-1]
    b = np.stack([leg + radius * np.cos(th), radius + radius * np.sin(th)], 1)
    c = np.stack([np.linspace(leg, 0, 41), np.full(41, 2 * radius)], 1)
    return np.vstack([a, b, c])


def circle_path(radius: float = 1.5) -> np.ndarray:
    th = np.linspace(-math.pi / 2, 1.5 * math.pi, 200)
    return np.stack([radius * np.cos(th), radius + radius * np.sin(th)], 1)


@dataclass
class World:
    circles: list[tuple[float, float, float]] = field(default_factory=list)  # (cx, cy, r)
    n_beams: int = 360
    range_max: float = 5.0

    def scan(self, pose: np.ndarray) -> LaserScan2D:
        """Scan in the robot frame; inf where a beam hits nothing."""
        ang = -math.pi + np.arange(self.n_beams) * (2 * math.pi / self.n_beams)
        ranges = np.full(self.n_beams, np.inf)
        dirs = np.stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])], 1)
        for cx, cy, r in self.circles:
            oc = np.array([pose[0] - cx, pose[1] - cy])
            b = dirs @ oc
            c = oc @ oc - r * r
            disc = b * b - c
            hit = disc >= 0
            t = -b - np.sqrt(np.where(hit, disc, 0.0))
            t = np.where(hit & (t > 0), t, np.inf)
            ranges = np.minimum(ranges, t)
        ranges[ranges > self.range_max] = np.inf
        return LaserScan2D(ranges=ranges, angle_min=-math.pi, angle_increment=2 * math.pi / self.n_beams,
                           range_max=self.range_max)

    def boundary_points(self) -> np.ndarray:
        if not self.circles:
            return np.zeros((0, 2))
        th = np.linspace(0, 2 * math.pi, 180, endpoint=False)
        return np.vstack([np.stack([cx + r * np.cos(th), cy + r * np.sin(th)], 1) for cx, cy, r in self.circles])


@dataclass
class RunResult:
    reached: bool
    steps: int
    min_clearance: float
    poses: np.ndarray
    statuses: list


def run_closed_loop(controller, robot: RobotConfig, world: World, start_pose, max_steps: int = 600,
                    dt: float = 0.1, use_scan: bool = True) -> RunResult:
    pose = np.asarray(start_pose, dtype=np.float64)
    vel = np.zeros(3)
    boundary = world.boundary_points()
    min_clear = math.inf
    poses = [pose]
    statuses = []
    for step in range(max_steps):
        scan = world.scan(pose) if use_scan else None
        res = controller.compute(pose, vel, scan)
        statuses.append(res.status.value)
        if res.status.value == "goal_reached":
            return RunResult(True, step, min_clear, np.array(poses), statuses)
        vel = np.asarray(res.command, dtype=np.float64)
        pose = integrate(pose, vel, dt)
        poses.append(pose)
        if boundary.shape[0]:
            min_clear = min(min_clear, float(pose_clearance(robot, pose[None], boundary)[0]))
    return RunResult(False, max_steps, min_clear, np.array(poses), statuses)
