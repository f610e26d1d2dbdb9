"""The BARN evaluation protocol, independent of who drives: timer, outcome, scores, seeds.

From the official ``run.py`` (see /work/shared/benchmarks/barn/README.md):

- the timer starts once the robot has moved 0.1 m from where it started;
- a trial ends at the goal (centre within 1 m), at a collision (a failure) or at 100 s;
- the score is ``success * OT / clip(AT, 2 OT, 8 OT)`` with ``OT = path_length / 2 m/s``; the
  2022-23 rule clipped from 4 OT (best 0.25): both are reported (``metric``, ``metric_4t``);
- results are success, collision and timeout rates, mean time and mean score, per world and
  over all trials.

Ours on top: every world is run with several seeds, each a different sensor noise, odometry
error and yaw gain (:func:`trial_seed`), and the navigator's compute time is charged: a
command computed from an observation at ``t`` acts at ``t + compute time`` (rounded up to
physics ticks), and a step that takes longer than the control period is a deadline miss
(:class:`ControlDeadline`).
"""
from __future__ import annotations

import math
import zlib
from collections.abc import Iterable

import attrs
import numpy as np

from .barn_worlds import BARN_GOAL_RADIUS, BARN_TIME_LIMIT, barn_metric

START_DISTANCE = 0.1  # m of motion before the timer starts
DEFAULT_SEEDS = 10


class MotionTimer:
    """The official timer: starts when the robot is ``START_DISTANCE`` from its start."""

    def __init__(self, start_xy: Iterable[float], distance: float = START_DISTANCE) -> None:
        self.start_xy = tuple(float(v) for v in start_xy)
        self.distance = float(distance)
        self.started_at: float | None = None

    def update(self, stamp: float, xy: Iterable[float]) -> None:
        if self.started_at is None and math.dist(self.start_xy, tuple(xy)[:2]) >= self.distance:
            self.started_at = float(stamp)

    def elapsed(self, stamp: float) -> float:
        """Seconds on the official clock (0 before the robot has moved)."""
        return 0.0 if self.started_at is None else float(stamp) - self.started_at


@attrs.define(frozen=True)
class TrialOutcome:
    reached: bool
    collided: bool
    timeout: bool
    time_s: float  # official time (from the first 0.1 m of motion)
    sim_time_s: float  # simulated time since the trial began

    @property
    def success(self) -> bool:
        return self.reached and not self.collided


class TrialMonitor:
    """Feed it the ground truth after every physics tick; it says when and how the trial ended."""

    def __init__(self, start_xy: Iterable[float], goal: Iterable[float], goal_radius: float = BARN_GOAL_RADIUS,
                 time_limit: float = BARN_TIME_LIMIT) -> None:
        self.goal = tuple(float(v) for v in goal)
        if not (goal_radius > 0 and time_limit > 0):
            raise ValueError(f"TrialMonitor needs goal_radius and time_limit > 0, got {goal_radius!r}, {time_limit!r}")
        self.goal_radius, self.time_limit = float(goal_radius), float(time_limit)
        self.timer = MotionTimer(start_xy)
        self.outcome: TrialOutcome | None = None

    def update(self, stamp: float, xy: Iterable[float], collided: bool) -> TrialOutcome | None:
        """The outcome once the trial is over (then always the same), else None."""
        if self.outcome is not None:
            return self.outcome
        xy = tuple(xy)[:2]
        self.timer.update(stamp, xy)
        elapsed = self.timer.elapsed(stamp)
        if collided:
            self.outcome = TrialOutcome(False, True, False, elapsed, stamp)
        elif math.dist(xy, self.goal) <= self.goal_radius:
            self.outcome = TrialOutcome(True, False, False, elapsed, stamp)
        elif elapsed >= self.time_limit - 1e-9 or (self.timer.started_at is None and stamp >= self.time_limit - 1e-9):
            # run.py's limit is on its own clock (from the first 0.1 m); a robot that never
            # moves would wait there forever: here it times out after the same limit.
            self.outcome = TrialOutcome(False, False, True, elapsed if self.timer.started_at is not None else self.time_limit, stamp)
        return self.outcome


class ControlDeadline:
    """Charges a navigator's compute time in a lockstep simulation.

    ``delay_ticks(compute_s)`` is how many physics ticks the command computed from the current
    observation waits before it acts (the old one keeps acting meanwhile), and each step that
    took longer than the control period counts as a deadline miss. ``speed`` scales measured
    wall time to the robot's computer (1 = this machine).
    """

    def __init__(self, period: float, tick: float, speed: float = 1.0) -> None:
        if not (period > 0 and tick > 0 and speed > 0):
            raise ValueError(f"ControlDeadline needs period, tick and speed > 0, got {period!r}, {tick!r}, {speed!r}")
        self.period, self.tick, self.speed = float(period), float(tick), float(speed)
        self.steps = 0
        self.misses = 0
        self.worst_s = 0.0
        self.total_s = 0.0

    def delay_ticks(self, compute_s: float) -> int:
        if not (math.isfinite(compute_s) and compute_s >= 0):
            raise ValueError(f"ControlDeadline: compute time must be a finite number >= 0, got {compute_s!r}")
        charged = compute_s / self.speed
        self.steps += 1
        self.total_s += charged
        self.worst_s = max(self.worst_s, charged)
        if charged > self.period:
            self.misses += 1
        return int(math.ceil(charged / self.tick - 1e-9))


def trial_seed(world: int | str, index: int, base: int = 0) -> int:
    """The seed of a world's ``index``-th trial: independent streams for every (world, index)
    (so adding worlds or seeds never changes the others), reproducible across runs."""
    key = zlib.crc32(str(world).encode())
    return int(np.random.SeedSequence([int(base), key, int(index)]).generate_state(1)[0])


@attrs.define(frozen=True)
class Trial:
    """One scored run of one world with one seed."""

    world: int | str
    seed: int
    success: bool
    collided: bool
    timeout: bool
    time_s: float
    metric: float
    metric_4t: float
    deadline_misses: int = 0
    control_steps: int = 0
    yaw_gain: float | None = None

    @classmethod
    def scored(cls, world: int | str, seed: int, outcome: TrialOutcome, path_length: float,
               deadline: ControlDeadline | None = None, yaw_gain: float | None = None) -> Trial:
        ok = outcome.success
        return cls(world, seed, ok, outcome.collided, outcome.timeout, outcome.time_s,
                   barn_metric(ok, outcome.time_s, path_length), barn_metric(ok, outcome.time_s, path_length, low=4.0),
                   deadline.misses if deadline else 0, deadline.steps if deadline else 0, yaw_gain)

    def as_json(self) -> dict:
        out = {"world": self.world, "seed": self.seed, "success": self.success, "collided": self.collided,
               "timeout": self.timeout, "time_s": round(self.time_s, 3), "metric": round(self.metric, 4),
               "metric_4t": round(self.metric_4t, 4), "deadline_misses": self.deadline_misses}
        if self.yaw_gain is not None:
            out["yaw_gain"] = round(self.yaw_gain, 4)
        return out


def summarize_trials(trials: list[Trial]) -> dict:
    """Rates, mean time of the successful trials, mean scores, deadline misses."""
    n = len(trials)
    if n == 0:
        return {"trials": 0, "success_rate": 0.0, "collision_rate": 0.0, "timeout_rate": 0.0, "mean_time_s": None,
                "mean_metric": 0.0, "metric_4t": 0.0, "deadline_misses": 0}
    ok = [t for t in trials if t.success]
    return {
        "trials": n,
        "success_rate": round(len(ok) / n, 4),
        "collision_rate": round(sum(t.collided for t in trials) / n, 4),
        "timeout_rate": round(sum(t.timeout for t in trials) / n, 4),
        "mean_time_s": round(sum(t.time_s for t in ok) / len(ok), 3) if ok else None,
        "mean_metric": round(sum(t.metric for t in trials) / n, 4),
        "metric_4t": round(sum(t.metric_4t for t in trials) / n, 4),
        "deadline_misses": sum(t.deadline_misses for t in trials),
    }


def per_world(trials: list[Trial]) -> dict:
    """``summarize_trials`` of each world's trials, by world, in first-seen order."""
    groups: dict[int | str, list[Trial]] = {}
    for t in trials:
        groups.setdefault(t.world, []).append(t)
    return {world: summarize_trials(group) for world, group in groups.items()}


def tuning_split(trials: list[Trial]) -> dict:
    """BARN worlds split as the issue asks: tune on index % 5 != 0, report % 5 == 0 apart.
    (Worlds with index % 6 == 0 are the held-out test set and are not shipped at all.)"""
    tune = [t for t in trials if isinstance(t.world, int) and t.world % 5 != 0]
    report = [t for t in trials if isinstance(t.world, int) and t.world % 5 == 0]
    return {"tune": summarize_trials(tune), "report": summarize_trials(report)}
