"""Run one BARN world under the challenge rules with a Navigator and score it."""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from ..barn_worlds import BARN_GOAL, BARN_GOAL_RADIUS, BARN_START, BARN_TIME_LIMIT, BarnWorld
from ..builders import from_barn
from ..clock import ClockMode, SimClock
from emos.actors.nav.navigator import Navigator, NavTask, Observation
from ..robots import JACKAL, RobotSpec
from ..sensors import Lidar, LidarConfig, Odometry, OdometryConfig


@attrs.define(frozen=True)
class EpisodeResult:
    idx: int
    success: bool
    collided: bool
    timeout: bool
    time_s: float
    metric: float
    distance_m: float = 0.0
    wall_s: float = 0.0
    reason: str = ""

    def as_json(self) -> dict:
        return {"idx": self.idx, "success": self.success, "collided": self.collided, "timeout": self.timeout,
                "time_s": round(self.time_s, 3), "metric": round(self.metric, 4)}


@attrs.define(frozen=True)
class BarnRules:
    """The challenge rules (BARN README) and our simulation rates."""

    start: tuple[float, float, float] = BARN_START
    goal: tuple[float, float] = BARN_GOAL
    goal_radius: float = BARN_GOAL_RADIUS
    time_limit: float = BARN_TIME_LIMIT
    robot: RobotSpec = JACKAL
    # UST-10LX geometry (270 deg, 1081 beams, 10 m) with 1 cm range noise; 20 Hz, where the
    # real one runs at 40, to keep the benchmark fast (the controller runs at 10 Hz anyway).
    lidar: LidarConfig = LidarConfig(noise_std=0.01)
    control_rate_hz: float = 10.0
    physics_dt: float = 0.01
    # The navigator's pose: ground-truth odometry (default), or drifting wheel odometry with
    # this much wheel slip (a harder, more realistic variant).
    noisy_odometry: bool = False
    slip: float = 0.02


def score_run(entry: BarnWorld, reached: bool, collided: bool, time_s: float, rules: BarnRules = BarnRules()) -> EpisodeResult:
    """Classify and score a finished run: success only if the goal was reached without a
    collision within the time limit; the metric is the official formula."""
    success = reached and not collided and time_s <= rules.time_limit
    timeout = not success and not collided
    return EpisodeResult(entry.idx, success, collided, timeout, float(time_s), entry.metric(success, time_s))


def nav_robot(spec: RobotSpec) -> Any:
    """The navigation core's description of a simulated robot (box footprint, limits)."""
    from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig

    return RobotConfig(
        model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([spec.length, spec.width, spec.height]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=spec.max_vx, max_acc=spec.max_acc_x, max_decel=spec.max_acc_x),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=spec.max_omega, max_acc=spec.max_acc_omega, max_decel=spec.max_acc_omega),
    )


def run_episode(entry: BarnWorld, navigator: Navigator, rules: BarnRules = BarnRules(), seed: int = 0,
                png_path: str | Path | None = None) -> EpisodeResult:
    """Drive the Jackal from start to goal in lock-step with the sim clock (faster than real time)."""
    wall0 = time.perf_counter()
    world = from_barn(entry, clock=SimClock(dt=rules.physics_dt, mode=ClockMode.LOCKSTEP), seed=seed)
    try:
        robot = world.add_robot(rules.robot, rules.start, slip=rules.slip if rules.noisy_odometry else 0.0)
        lidar = world.add_sensor(Lidar(robot, rules.lidar))
        odom = world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=rules.control_rate_hz,
                                                               noisy=rules.noisy_odometry)))
        navigator.reset(NavTask(nav_robot(rules.robot), rules.start, rules.goal, rules.goal_radius,
                                (*rules.lidar.mount_xy, rules.lidar.mount_yaw), rules.control_rate_hz, rules.robot.center_offset))
        ticks_per_control = max(1, int(round(1.0 / (rules.control_rate_hz * rules.physics_dt))))
        max_ticks = int(math.ceil(rules.time_limit / rules.physics_dt))
        world.step()  # first sensor readings
        reached = False
        reason = "time limit"
        for tick in range(max_ticks):
            if tick % ticks_per_control == 0:
                o = odom.latest
                obs = Observation(world.clock.now(), o.pose, o.twist, lidar.latest)
                robot.command(*navigator.step(obs))
            world.step()
            if robot.collided:
                c = robot.contacts[0] if robot.contacts else None
                reason = f"collision at ({c.position[0]:.2f}, {c.position[1]:.2f})" if c else "collision"
                break
            if math.dist(robot.pose[:2], rules.goal) <= rules.goal_radius:
                reached, reason = True, "goal"
                break
        t = world.clock.now()
        result = score_run(entry, reached, robot.collided, t, rules)
        result = attrs.evolve(result, distance_m=robot.distance_travelled, wall_s=time.perf_counter() - wall0, reason=reason)
        if png_path is not None:
            from ..render import render_topdown

            plan = getattr(navigator, "plan", None)
            status = "success" if result.success else ("collision" if result.collided else "timeout")
            render_topdown(world, png_path, plan=None if plan is None else np.asarray(plan), goal=rules.goal,
                           goal_radius=rules.goal_radius, bounds=(-5.0, -0.5, 0.5, 14.5), pixels_per_m=40,
                           title=f"BARN {entry.idx} {navigator.name}: {status} t={t:.1f}s metric={result.metric:.3f}")
        return result
    finally:
        world.close()
