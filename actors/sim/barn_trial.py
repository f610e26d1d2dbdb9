"""One BARN / DynaBARN trial under the protocol, in lockstep, with the driver's compute charged.

Independent of any navigator interface: the driver is a *policy*, a callable
``policy(stamp, odometry, scan) -> (vx, vy, omega)`` called at the control rate with the
latest odometry reading and scan (a harness adapts its navigator to it).

Configurations (:class:`TrialSpec`):

- realistic (the default): ``jackal-barn`` (calibrated skid-steer drive, per-episode yaw
  gain, 0.25 s watchdog, chassis + wheels collision shape; or ``jackal-wheeled``), the
  Jackal's laser (720 beams, 270 deg, 30 m, 50 Hz, noise, 0.055 m ahead) and wheel + IMU
  odometry; the policy's compute time is charged (see ``barn_protocol.ControlDeadline``);
- ``ideal=True``: the configuration ``emos bench barn`` measured before: kinematic box
  Jackal, a UST-10-like lidar (1081 beams, 10 m, 20 Hz, 1 cm noise), ground-truth odometry
  and free compute.

Each seed of a world (``barn_protocol.trial_seed``) draws its own sensor noise, odometry
errors and yaw gain.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import attrs
import numpy as np

from .barn_protocol import ControlDeadline, Trial, TrialMonitor
from .barn_worlds import BARN_GOAL, BARN_GOAL_RADIUS, BARN_START, BARN_TIME_LIMIT, BarnWorld
from .clock import ClockMode, SimClock
from .dynabarn import DynaWorld
from .jackal import JACKAL_LASER, JACKAL_ODOMETRY
from .sensors import Lidar, LidarConfig, Odometry, OdometryConfig, WheelImuOdometry

Policy = Callable[[float, Any, Any], tuple[float, float, float]]

# The lidar of the ideal configuration (what bench barn used before): UST-10LX geometry,
# 20 Hz, 10 m, 1 cm noise.
IDEAL_LIDAR = LidarConfig(noise_std=0.01)


def _rate(instance: object, attribute: attrs.Attribute, value: float) -> None:
    if not value > 0:
        raise ValueError(f"TrialSpec.{attribute.name} must be > 0, got {value!r}")


@attrs.define(frozen=True)
class TrialSpec:
    ideal: bool = False
    robot: str = attrs.field(default="jackal-barn", validator=attrs.validators.in_(("jackal-barn", "jackal-wheeled")))
    """Robot of the realistic configuration (``--ideal`` always uses the kinematic box Jackal)."""
    control_rate_hz: float = attrs.field(default=10.0, validator=_rate)
    physics_dt: float = attrs.field(default=0.01, validator=_rate)
    compute_speed: float = attrs.field(default=1.0, validator=_rate)
    """How fast the robot's computer is relative to this machine's thread CPU time."""
    time_limit: float = attrs.field(default=BARN_TIME_LIMIT, validator=_rate)
    charge_compute: bool = True
    """Realistic configuration: delay each command by the policy's measured compute time. The
    charge varies a little with the machine (a tick more or less), so charged runs are not
    bit-reproducible; False gives reproducible runs (and no deadline accounting)."""
    goal_radius: float = attrs.field(default=BARN_GOAL_RADIUS, validator=_rate)
    noisy_odometry: bool = False
    """Ideal configuration only: drifting wheel odometry with ``slip`` instead of ground truth
    (the old ``--noisy-odometry`` variant; the realistic configuration has its own)."""
    slip: float = attrs.field(default=0.02, converter=float)

    def __attrs_post_init__(self) -> None:
        if self.noisy_odometry and not self.ideal:
            raise ValueError("TrialSpec.noisy_odometry is a variant of the ideal configuration (ideal=True); the "
                             "realistic one always navigates on wheel + IMU odometry")
        if not 0.0 <= self.slip < 1.0:
            raise ValueError(f"TrialSpec.slip must be in [0, 1), got {self.slip!r}")

    @property
    def robot_name(self) -> str:
        return "jackal" if self.ideal else self.robot

    @property
    def lidar(self) -> LidarConfig:
        return IDEAL_LIDAR if self.ideal else JACKAL_LASER

    @property
    def charges_compute(self) -> bool:
        return self.charge_compute and not self.ideal


#: The default spec of :func:`build_trial` and :func:`run_trial` (frozen, so one instance is shared).
DEFAULT_TRIAL_SPEC = TrialSpec()


@attrs.define(eq=False)
class TrialWorld:
    """A built trial: the world and its robot and sensors, and where to go."""

    key: int | str
    world: Any
    robot: Any
    lidar: Lidar
    odometry: Odometry | WheelImuOdometry
    start: tuple[float, float, float]
    goal: tuple[float, float]
    path_length: float

    def close(self) -> None:
        self.world.close()


def world_key(entry: BarnWorld | DynaWorld) -> int | str:
    return entry.idx if isinstance(entry, BarnWorld) else f"dynabarn:{entry.idx}"


def start_and_goal(entry: BarnWorld | DynaWorld) -> tuple[tuple[float, float, float], tuple[float, float]]:
    """Where a trial of ``entry`` starts (x, y, yaw) and where its goal is (x, y)."""
    if isinstance(entry, BarnWorld):
        return BARN_START, BARN_GOAL
    if isinstance(entry, DynaWorld):
        return entry.start, entry.goal
    raise TypeError(f"expected a BarnWorld or a DynaWorld, got {type(entry).__name__}")


def build_trial(entry: BarnWorld | DynaWorld, seed: int, spec: TrialSpec = DEFAULT_TRIAL_SPEC) -> TrialWorld:
    """The world of ``entry`` with the spec's robot and sensors, seeded with ``seed``."""
    clock = SimClock(dt=spec.physics_dt, mode=ClockMode.LOCKSTEP)
    if isinstance(entry, BarnWorld):
        from .builders import from_barn

        world = from_barn(entry, clock=clock, seed=seed)
    elif isinstance(entry, DynaWorld):
        from .dynabarn import from_dynabarn

        world = from_dynabarn(entry, clock=clock, seed=seed)
    else:
        raise TypeError(f"build_trial needs a BarnWorld or a DynaWorld, got {type(entry).__name__}")
    start, goal = start_and_goal(entry)
    try:
        slip = spec.slip if spec.noisy_odometry else 0.0
        robot = world.add_robot(spec.robot_name, start, slip=slip)
        lidar = world.add_sensor(Lidar(robot, spec.lidar))
        odometry: Odometry | WheelImuOdometry
        if spec.ideal:
            odometry = world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=spec.control_rate_hz,
                                                                       noisy=spec.noisy_odometry)))
        else:
            odometry = world.add_sensor(WheelImuOdometry(robot, JACKAL_ODOMETRY))
        return TrialWorld(world_key(entry), world, robot, lidar, odometry, start, goal, entry.path_length)
    except BaseException:
        world.close()
        raise


def run_trial(trial: TrialWorld, policy: Policy, spec: TrialSpec = DEFAULT_TRIAL_SPEC, seed: int = 0) -> Trial:
    """Drive ``trial`` with ``policy`` until the protocol ends it; the world stays open."""
    world, robot = trial.world, trial.robot
    dt = world.clock.dt
    ticks_per_control = max(1, int(round(1.0 / (spec.control_rate_hz * dt))))
    monitor = TrialMonitor(trial.start[:2], trial.goal, spec.goal_radius, spec.time_limit)
    deadline = ControlDeadline(1.0 / spec.control_rate_hz, dt, spec.compute_speed)
    pending: list[tuple[int, np.ndarray]] = []  # (tick at which it acts, command)
    world.step()  # first readings
    tick = 0
    outcome = None
    # Trials end by the monitor; the cap only guards against a monitor that never decides.
    max_ticks = int(np.ceil(4 * spec.time_limit / dt))
    while outcome is None and tick < max_ticks:
        if tick % ticks_per_control == 0:
            cpu0 = time.thread_time()
            command = np.asarray(policy(world.clock.now(), trial.odometry.latest, trial.lidar.latest), dtype=float)
            spent = time.thread_time() - cpu0
            delay = deadline.delay_ticks(spent) if spec.charges_compute else 0
            pending.append((tick + delay, command))
        due = [c for t, c in pending if t <= tick]
        if due:
            robot.command(*due[-1])
            pending = [(t, c) for t, c in pending if t > tick]
        world.step()
        tick += 1
        outcome = monitor.update(world.clock.now(), robot.pose[:2], robot.collided)
    if outcome is None:
        raise RuntimeError(f"trial {trial.key}: no outcome after {max_ticks} ticks (time limit {spec.time_limit} s)")
    gain = getattr(robot.drive, "yaw_gain", None)
    return Trial.scored(trial.key, seed, outcome, trial.path_length, deadline if spec.charges_compute else None, gain)
