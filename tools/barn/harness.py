"""Run one BARN (or DynaBARN-style) world under the challenge rules with a Navigator and score it.

The trial itself (robot, sensors, lockstep loop, official timer, charged compute time) is
``barn_trial``; this adapts a navigation ``Navigator`` to it and adds the episode's picture.
``BarnRules`` is its :class:`~emos.actors.sim.barn_trial.TrialSpec`: realistic by default
(skid-steer Jackal, its laser, wheel + IMU odometry, compute charged), ``ideal=True`` for
the kinematic robot of the first benchmark.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from emos.actors.nav.navigator import Navigator, NavTask, Observation
from emos.actors.sim.barn_protocol import TrialOutcome
from emos.actors.sim.barn_trial import TrialSpec, build_trial, run_trial
from emos.actors.sim.barn_worlds import BarnWorld
from emos.actors.sim.dynabarn import DynaWorld
from emos.actors.sim.robots import RobotSpec

BarnRules = TrialSpec
DEFAULT_RULES = BarnRules()  # frozen: one shared default is safe


@attrs.define(frozen=True)
class EpisodeResult:
    idx: int
    success: bool
    collided: bool
    timeout: bool
    time_s: float  # official time: from the first 0.1 m of motion
    metric: float  # success * OT / clip(t, 2 OT, 8 OT)
    seed: int = 0
    metric_4t: float = 0.0  # the 2022-23 rule: clip from 4 OT
    deadline_misses: int = 0
    yaw_gain: float | None = None  # the skid-steer episode's draw (None: ideal robot)
    distance_m: float = 0.0
    wall_s: float = 0.0
    reason: str = ""

    def as_json(self) -> dict:
        return {"idx": self.idx, "success": self.success, "collided": self.collided, "timeout": self.timeout,
                "time_s": round(self.time_s, 3), "metric": round(self.metric, 4), "seed": self.seed,
                "metric_4t": round(self.metric_4t, 4), "deadline_misses": self.deadline_misses}


def score_run(entry: BarnWorld | DynaWorld, reached: bool, collided: bool, time_s: float,
              rules: TrialSpec = DEFAULT_RULES) -> EpisodeResult:
    """Classify and score a finished run (official time): success only if the goal was reached
    without a collision within the time limit."""
    from emos.actors.sim.barn_protocol import Trial

    timed_out = not collided and (not reached or time_s > rules.time_limit)
    outcome = TrialOutcome(reached and not timed_out, collided, timed_out, float(time_s), float(time_s))
    t = Trial.scored(entry.idx, 0, outcome, entry.path_length)
    return EpisodeResult(entry.idx, t.success, t.collided, t.timeout, t.time_s, t.metric, metric_4t=t.metric_4t)


def nav_robot(spec: RobotSpec) -> Any:
    """The navigation core's description of a simulated robot (box footprint, limits)."""
    from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig

    return RobotConfig(
        model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([spec.length, spec.width, spec.height]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=spec.max_vx, max_acc=spec.max_acc_x, max_decel=spec.max_acc_x),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=spec.max_omega, max_acc=spec.max_acc_omega, max_decel=spec.max_acc_omega),
    )


def picture_bounds(entry: BarnWorld | DynaWorld) -> tuple[float, float, float, float]:
    """The window of a trial's top-down picture: the BARN course, or the whole moving-obstacle
    corridor (both side walls: a crosser can push the robot against either) with a margin."""
    if isinstance(entry, BarnWorld):
        return (-5.0, -0.5, 0.5, 14.5)
    ends = np.array([end for wall in entry.walls() for end in (wall.start, wall.end)], dtype=float)
    (xmin, ymin), (xmax, ymax) = ends.min(axis=0) - 0.5, ends.max(axis=0) + 0.5
    return (float(xmin), float(ymin), float(xmax), float(ymax))


def picture_title(trial: Any, result: EpisodeResult, navigator: str) -> str:
    status = "success" if result.success else ("collision" if result.collided else "timeout")
    return f"{trial.key} seed {result.seed} {navigator}: {status} t={result.time_s:.1f}s metric={result.metric:.3f}"


def run_episode(entry: BarnWorld | DynaWorld, navigator: Navigator, rules: TrialSpec = DEFAULT_RULES, seed: int = 0,
                png_path: str | Path | None = None) -> EpisodeResult:
    """Drive the Jackal from start to goal in lock-step with the sim clock (faster than real time)."""
    wall0 = time.perf_counter()
    trial = build_trial(entry, seed, rules)
    try:
        spec, lidar = trial.robot.spec, trial.lidar.config
        navigator.reset(NavTask(nav_robot(spec), trial.start, trial.goal, rules.goal_radius,
                                (*lidar.mount_xy, lidar.mount_yaw), rules.control_rate_hz, spec.center_offset))

        def policy(stamp: float, odom: Any, scan: Any) -> tuple[float, float, float]:
            return navigator.step(Observation(stamp, odom.pose, odom.twist, scan))

        t = run_trial(trial, policy, rules, seed)
        robot = trial.robot
        if t.collided:
            c = robot.contacts[0] if robot.contacts else None
            reason = f"collision at ({c.position[0]:.2f}, {c.position[1]:.2f})" if c else "collision"
        else:
            reason = "goal" if t.success else "time limit"
        result = EpisodeResult(entry.idx, t.success, t.collided, t.timeout, t.time_s, t.metric, seed, t.metric_4t,
                               t.deadline_misses, t.yaw_gain, robot.distance_travelled, time.perf_counter() - wall0, reason)
        if png_path is not None:
            from emos.actors.sim.render import render_topdown

            plan = getattr(navigator, "plan", None)
            render_topdown(trial.world, png_path, plan=None if plan is None else np.asarray(plan), goal=trial.goal,
                           goal_radius=rules.goal_radius, bounds=picture_bounds(entry), pixels_per_m=40,
                           title=picture_title(trial, result, navigator.name))
        return result
    finally:
        trial.close()
