"""Recovery behaviors (Nav2's behavior server: spin, back up, drive on heading, wait), as pure
planners over obstacle points in the robot frame.

Each planner checks the robot's footprint over the WHOLE motion before it starts (every pose of
the rotation or the straight drive, through :func:`~emos.actors.nav.controllers.clearance.pose_clearance`,
the one home of footprint clearance) and returns a :class:`BehaviorPlan`: feasible with its
commands, or refused with the reason a person can act on ("back_up refused: obstacle 0.12 m
behind"). The ``Behaviors`` component (components/behaviors.py) re-plans the remaining motion on
every fresh scan while it plays one, so an obstacle that appears mid-way stops it too.

Backing up is where today's unblock maneuvers are blind: a 270 degree scan sees nothing behind
the robot. :func:`plan_back_up` therefore refuses when nothing covers the rear (``rear_seen``
False: no scan beam behind and no local map) instead of driving into the unseen.

Giving way to a person (:func:`plan_give_way`, :class:`GiveWayConfig`) is a recovery move of
the same kind: the robot stands, backs out of a passage or pulls aside, whichever keeps it out
of the predicted path of the movers the scan tracker sees, never towards one that is near.
"""
from __future__ import annotations

import math
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from .controllers.clearance import pose_clearance
from .robot import RobotConfig

__all__ = ["BehaviorPlan", "GiveWayConfig", "GiveWayMove", "give_way_times", "plan_give_way", "plan_spin", "plan_drive_on_heading", "plan_back_up", "plan_wait", "rear_covered", "scan_covers_rear"]

POSE_STEP = 0.01  # m between checked poses of a straight drive
ANGLE_STEP = math.radians(2.0)  # rad between checked poses of a spin


@attrs.define(frozen=True)
class BehaviorPlan:
    """``commands``: (N, 3) (vx, vy, omega) for N steps of ``dt`` s; empty when refused."""

    name: str
    feasible: bool
    commands: np.ndarray
    dt: float
    reason: str = ""

    @property
    def duration(self) -> float:
        return float(self.commands.shape[0]) * self.dt


def _refuse(name: str, dt: float, reason: str) -> BehaviorPlan:
    return BehaviorPlan(name, False, np.zeros((0, 3)), dt, f"{name} refused: {reason}")


def _check_number(name: str, what: str, value: float, positive: bool = True) -> float:
    v = float(value)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{name}: {what} must be a finite number{' > 0' if positive else ''}, got {value!r}")
    return v


def _points(obstacles: np.ndarray | None) -> np.ndarray:
    pts = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
    return pts[np.all(np.isfinite(pts), axis=1)]


def plan_spin(robot: RobotConfig, obstacles: np.ndarray | None, angle: float, *, max_omega: float = 0.5,
              dt: float = 0.1, margin: float = 0.02) -> BehaviorPlan:
    """Rotate in place by ``angle`` rad (sign = direction). Refused when the footprint at any
    heading of the rotation comes within ``margin`` m of an obstacle (a round robot only when it
    touches already; a long one when a corner would swing into something)."""
    name = "spin"
    angle = _check_number(name, "angle", angle, positive=False)
    w = _check_number(name, "max_omega", max_omega)
    dt = _check_number(name, "dt", dt)
    if abs(angle) < 1e-6:
        return BehaviorPlan(name, True, np.zeros((0, 3)), dt, "nothing to turn")
    steps = max(2, int(math.ceil(abs(angle) / ANGLE_STEP)) + 1)
    yaws = np.linspace(0.0, angle, steps)
    poses = np.c_[np.zeros(steps), np.zeros(steps), yaws]
    clear = pose_clearance(robot, poses, _points(obstacles))
    if np.any(clear < margin):
        i = int(np.argmax(clear < margin))
        return _refuse(name, dt, f"the footprint would come within {max(clear[i], 0.0):.2f} m of an obstacle "
                                 f"after {math.degrees(abs(yaws[i])):.0f} deg of the {math.degrees(abs(angle)):.0f} deg turn "
                                 f"(margin {margin:g} m)")
    n = max(1, int(math.ceil(abs(angle) / (w * dt))))
    omega = angle / (n * dt)
    return BehaviorPlan(name, True, np.tile([0.0, 0.0, omega], (n, 1)), dt)


def _straight(name: str, robot: RobotConfig, obstacles: np.ndarray | None, distance: float, speed: float,
              dt: float, margin: float, direction: float) -> BehaviorPlan:
    distance = _check_number(name, "distance", distance)
    speed = _check_number(name, "speed", abs(float(speed)))
    dt = _check_number(name, "dt", dt)
    steps = max(2, int(math.ceil(distance / POSE_STEP)) + 1)
    s = np.linspace(0.0, distance, steps)
    poses = np.c_[direction * s, np.zeros(steps), np.zeros(steps)]
    clear = pose_clearance(robot, poses, _points(obstacles))
    if np.any(clear < margin):
        i = int(np.argmax(clear < margin))
        free = max(0.0, float(s[i - 1])) if i > 0 else 0.0
        side = "behind" if direction < 0 else "ahead"
        # How far the nearest obstacle on the way is from the footprint, now.
        gap = _gap(robot, poses[0], _points(obstacles), direction)
        return _refuse(name, dt, f"obstacle {gap:.2f} m {side} (the footprint would come within {margin:g} m "
                                 f"after {free:.2f} m of the {distance:.2f} m)")
    n = max(1, int(math.ceil(distance / (speed * dt))))
    v = direction * distance / (n * dt)
    return BehaviorPlan(name, True, np.tile([v, 0.0, 0.0], (n, 1)), dt)


def _gap(robot: RobotConfig, pose: np.ndarray, pts: np.ndarray, direction: float) -> float:
    """Clearance of the footprint to the nearest point on the driving side of the robot."""
    side = pts[(pts[:, 0] * direction) > 0.0] if pts.shape[0] else pts
    if side.shape[0] == 0:
        return math.inf
    return max(0.0, float(pose_clearance(robot, pose[None, :], side)[0]))


def plan_drive_on_heading(robot: RobotConfig, obstacles: np.ndarray | None, distance: float, *, speed: float = 0.2,
                          dt: float = 0.1, margin: float = 0.05) -> BehaviorPlan:
    """Drive straight ahead ``distance`` m at ``speed`` m/s (Nav2's DriveOnHeading), footprint checked."""
    return _straight("drive_on_heading", robot, obstacles, distance, speed, dt, margin, 1.0)


def rear_covered(angle_min: float, angle_max: float, half_width: float = math.radians(30.0)) -> bool:
    """Whether a scan spanning [angle_min, angle_max] (robot frame) sees the rear sector
    (pi - half_width .. pi + half_width)."""
    span = angle_max - angle_min
    if span >= 2 * math.pi - 1e-6:
        return True
    # Every direction of the rear sector must lie inside the scan's interval (on the circle).
    rear = np.linspace(math.pi - half_width, math.pi + half_width, 31)
    return bool(np.all(np.mod(rear - angle_min, 2 * math.pi) <= span + 1e-9))


def scan_covers_rear(scan: Any) -> bool:
    """:func:`rear_covered` for a LaserScan2D (its beams span angle_min + i * angle_increment)."""
    n = int(np.asarray(scan.ranges).size)
    inc = float(scan.angle_increment) if scan.angle_increment else 2 * math.pi / max(n, 1)
    return rear_covered(float(scan.angle_min), float(scan.angle_min) + inc * n)


def plan_back_up(robot: RobotConfig, obstacles: np.ndarray | None, distance: float, *, speed: float = 0.1,
                 dt: float = 0.1, margin: float = 0.05, rear_seen: bool = True) -> BehaviorPlan:
    """Drive straight back ``distance`` m (Nav2's BackUp). Refused when an obstacle behind would
    come within ``margin`` m of the footprint, or when nothing sees behind the robot."""
    if not rear_seen:
        dt = _check_number("back_up", "dt", dt)
        return _refuse("back_up", dt, "nothing sees behind the robot (the scan does not cover the rear and "
                                      "there is no local map): it will not back up blind")
    return _straight("back_up", robot, obstacles, distance, speed, dt, margin, -1.0)


def plan_wait(duration: float, *, dt: float = 0.1) -> BehaviorPlan:
    """Stand still ``duration`` s (zero commands)."""
    duration = _check_number("wait", "duration", duration)
    dt = _check_number("wait", "dt", dt)
    return BehaviorPlan("wait", True, np.zeros((max(1, int(math.ceil(duration / dt))), 3)), dt)


# -- give way to a moving obstacle -----------------------------------------------------------------

@attrs.define(frozen=True, kw_only=True)
class GiveWayConfig:
    """When and how the ``Behaviors`` give way to a moving obstacle (a person) tracked in the scan.

    ``enabled``: watch for movers on every step and give way on one's own (else only as an
    action / event method). A mover is *on a collision course* when, both at constant velocity
    (the robot at its odometry's), the gap between the robot's circle and the mover's is
    predicted to fall below ``personal_space`` m within ``time_before_collision`` s (Nav2's
    collision monitor's name for the same look-ahead) while it approaches, or when a mover is
    nearer than ``near_distance`` m and not moving away (a person turning round has no
    velocity to predict with yet). Movers farther than ``detection_range`` m are ignored.

    Giving way: every step the yield moves (constant twists up to ``speed`` m/s and the
    behavior server's ``max_rotational_vel``, checked against the static obstacles over
    ``simulate_ahead_time`` s, Nav2's name) are scored by the least predicted gap to every mover;
    then standing where the move ends for ``hold_time`` s more while the movers walk on (a move
    is only good if the robot is out of the way at its end: backing out along a person's way
    only puts off the contact); standing still wins when it keeps ``personal_space``, else the
    move that keeps the largest gap (backing out of a doorway, pulling aside into free space). The robot never moves towards
    a mover nearer than ``near_distance``. It is done when no mover has been on a collision
    course for ``clear_time`` s (the way is clear: the Controller drives again), and gives up
    after ``time_allowance`` s (Nav2's name)."""

    enabled: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    time_before_collision: float = attrs.field(default=3.0, validator=V.number(gt=0, le=30, finite=True, what="seconds"))
    personal_space: float = attrs.field(default=0.25, validator=V.number(ge=0, le=3, finite=True, what="metres"))
    near_distance: float = attrs.field(default=0.45, validator=V.number(ge=0, le=3, finite=True, what="metres"))
    detection_range: float = attrs.field(default=4.0, validator=V.number(gt=0, le=30, finite=True, what="metres"))
    clear_time: float = attrs.field(default=1.5, validator=V.number(ge=0, le=60, finite=True, what="seconds"))
    time_allowance: float = attrs.field(default=30.0, validator=V.number(gt=0, le=3600, finite=True, what="seconds"))
    speed: float = attrs.field(default=0.3, validator=V.number(gt=0, le=2, finite=True, what="m/s"))
    simulate_ahead_time: float = attrs.field(default=4.0, validator=V.number(gt=0, le=10, finite=True, what="seconds"))
    hold_time: float = attrs.field(default=4.0, validator=V.number(ge=0, le=30, finite=True, what="seconds"))

    def __attrs_post_init__(self) -> None:
        if self.near_distance < self.personal_space:
            raise ValueError(f"GiveWayConfig.near_distance ({self.near_distance} m) must be >= personal_space "
                             f"({self.personal_space} m): a mover inside the personal space is near")


@attrs.define(frozen=True)
class GiveWayMove:
    """One step of giving way: ``command`` (vx, vy, omega) for now, ``name`` of the move
    (``stand``, ``back_out``, ``pull_aside``, ``move_on``), ``gap`` (m: the least predicted gap
    to a mover over the look-ahead if the robot keeps this move)."""

    command: np.ndarray
    name: str
    gap: float
    index: int = -1  # which candidate (pass it back as ``previous`` next step)


COMFORT = 0.3  # m beyond the personal space: a larger predicted gap is no better (the least effort wins)
KEEP_BONUS = 0.08  # m of predicted gap the move of the last step is given over the others (no dithering)
BAND_WEIGHT = 0.5  # m of predicted gap a move loses per m its end lies inside the movers' band


def _candidates(speed: float, max_omega: float, n: int, dt: float) -> tuple[np.ndarray, list[str]]:
    """Yield moves as (C, n, 2) (v, omega) sequences and their names: standing; constant twists
    (v in +-speed, +-speed/2, 0; omega in +-max, +-max/2, 0); and turns in place to +-45, +-90,
    +-135 degrees followed by a drive forward at ``speed`` (pulling aside) or, to +-45 and +-90,
    backward (backing out at an angle)."""
    seqs: list[np.ndarray] = []
    names: list[str] = []
    for v in speed * np.array([0.0, -1.0, -0.5, 0.5, 1.0]):
        for w in max_omega * np.array([0.0, -1.0, -0.5, 0.5, 1.0]):
            seqs.append(np.tile([v, w], (n, 1)))
            names.append("stand" if v == 0.0 and w == 0.0 else "turn" if v == 0.0 else "back_out" if v < 0.0 else
                         "move_on" if w == 0.0 else "pull_aside")
    for deg, direction in [(d, 1.0) for d in (45, 90, 135)] + [(d, -1.0) for d in (45, 90)]:
        turn_steps = int(math.ceil(math.radians(deg) / (max_omega * dt)))
        for sign in (-1.0, 1.0):
            seq = np.zeros((n, 2))
            seq[:turn_steps, 1] = sign * math.radians(deg) / (turn_steps * dt)
            seq[turn_steps:, 0] = direction * speed
            seqs.append(seq)
            names.append("pull_aside" if direction > 0 else "back_out")
    return np.stack(seqs), names


def give_way_times(config: GiveWayConfig, dt: float) -> np.ndarray:
    """The times (s from now) :func:`plan_give_way` rolls its moves out over: ``simulate_ahead_time``,
    then standing ``hold_time`` at the move's end."""
    n, n_hold = _give_way_steps(config, dt)
    return np.arange(n + n_hold) * dt


def _give_way_steps(config: GiveWayConfig, dt: float) -> tuple[int, int]:
    """Poses a yield move is rolled out over (the start included), then steps standing at its end."""
    return max(2, int(math.ceil(config.simulate_ahead_time / dt)) + 1), (int(math.ceil(config.hold_time / dt)) if config.hold_time > 0 else 0)


def plan_give_way(robot: RobotConfig, obstacles: np.ndarray | None, centres: np.ndarray, velocities: np.ndarray,
                  radii: np.ndarray, config: GiveWayConfig, *, max_omega: float = 0.5, dt: float = 0.1,
                  margin: float = 0.03, previous: int | None = None, band: np.ndarray | None = None,
                  band_clearance: float = 0.55, futures: np.ndarray | None = None,
                  future_radii: np.ndarray | None = None) -> GiveWayMove:
    """The best yield move now, in the robot frame: ``obstacles`` (N, 2) static points (the
    movers' own points left out), the movers' ``centres`` (M, 2) and ``velocities`` (M, 2) in
    the robot frame, ``radii`` (M,). The moves of :func:`_candidates` are rolled out over
    ``simulate_ahead_time`` s and cut where the footprint would come within ``margin`` of a
    static point (the robot stops there); a move that takes the robot towards a mover nearer
    than ``near_distance`` is out. The move with the largest least gap to every mover's
    prediction wins, gaps beyond ``personal_space`` + ``COMFORT`` counting alike (then the
    least effort: standing, if it keeps that far). ``previous`` (the ``index`` of the move of
    the last step) keeps that move while it is nearly as good (``KEEP_BONUS`` m), so the robot
    does not dither between moves. ``band`` (K, 2): where movers walked (robot frame, e.g. the
    passage guard's ``MoverMemory.band_cells``): a move that ends nearer than ``band_clearance``
    to it is worse by ``BAND_WEIGHT`` x how far in (wait off the people's way, not in it).
    ``futures`` (P, T, 2), ``future_radii`` (P,): other ways the movers may go, in the robot frame
    at the times :func:`give_way_times` (e.g. as earlier walks from where one is went on: a
    person turning at the corner of their walk, where their straight line would not); the gaps
    to them count as the gaps to the straight lines do."""
    dt = _check_number("give_way", "dt", dt)
    w = _check_number("give_way", "max_omega", max_omega)
    pts = _points(obstacles)
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    velocities = np.asarray(velocities, dtype=float).reshape(-1, 2)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    n, n_hold = _give_way_steps(config, dt)
    seqs, names = _candidates(config.speed, w, n - 1, dt)
    # Poses after each step (C, n): the start, then the unicycle integrated at mid-step headings.
    v, om = seqs[..., 0], seqs[..., 1]
    th = np.concatenate([np.zeros((len(seqs), 1)), np.cumsum(om * dt, axis=1)], axis=1)
    mid = 0.5 * (th[:, :-1] + th[:, 1:])
    x = np.concatenate([np.zeros((len(seqs), 1)), np.cumsum(v * np.cos(mid) * dt, axis=1)], axis=1)
    y = np.concatenate([np.zeros((len(seqs), 1)), np.cumsum(v * np.sin(mid) * dt, axis=1)], axis=1)
    # Static obstacles: the robot drives until the footprint would come within the margin, then
    # stands. A point already too near only stops a move that brings it nearer.
    clear = pose_clearance(robot, np.stack([x, y, th], axis=-1), pts)
    bad = (clear < margin) & (clear < clear[:, :1] - 1e-3)
    stop_at = np.where(bad.any(axis=1), np.argmax(bad, axis=1) - 1, n - 1)
    idx = np.minimum(np.arange(n)[None, :], np.maximum(stop_at, 0)[:, None])
    px, py, pth = (np.take_along_axis(a, idx, axis=1) for a in (x, y, th))
    moving = np.arange(n)[None, :] < stop_at[:, None]
    vel = np.concatenate([v, np.zeros((len(seqs), 1))], axis=1) * moving
    # Then standing at the move's end for hold_time s while the movers walk on.
    if n_hold:
        px, py, pth = (np.concatenate([a, np.repeat(a[:, -1:], n_hold, axis=1)], axis=1) for a in (px, py, pth))
        vel = np.concatenate([vel, np.zeros((len(seqs), n_hold))], axis=1)
    t = np.arange(n + n_hold) * dt
    # Where every mover will be (T, M, 2): at constant velocity, then each other way given.
    ahead = centres[None, :, :] + velocities[None, :, :] * t[:, None, None]
    if futures is not None and len(futures):
        futures = np.asarray(futures, dtype=float)
        if futures.ndim != 3 or futures.shape[1:] != (len(t), 2):
            raise ValueError(f"give_way futures: expected (P, {len(t)}, 2) points at give_way_times, got shape {futures.shape}")
        ahead = np.concatenate([ahead, futures.transpose(1, 0, 2)], axis=1)
        radii = np.concatenate([radii, np.asarray(future_radii, dtype=float).reshape(-1)])
    if ahead.shape[1]:  # predicted gaps (C, n + n_hold, M) to every predicted mover
        dx = ahead[None, :, :, 0] - px[..., None]
        dy = ahead[None, :, :, 1] - py[..., None]
        dist = np.hypot(dx, dy)
        gap = np.nan_to_num(dist - robot.radius - radii[None, None, :], nan=np.inf)  # NaN: a way not known that far
        toward = (vel[..., None] * (np.cos(pth)[..., None] * dx + np.sin(pth)[..., None] * dy)) / np.maximum(dist, 1e-9)
        forbidden = np.any((gap < config.near_distance) & (toward > 0.02), axis=(1, 2))
        least = gap.min(axis=(1, 2))
    else:
        forbidden = np.zeros(len(seqs), dtype=bool)
        least = np.full(len(seqs), np.inf)
    forbidden[0] = False  # standing (the first candidate) is always possible
    effort = np.abs(v).mean(axis=1) / config.speed + 0.5 * np.abs(om).mean(axis=1) / w
    # Gaps beyond a comfortable distance are all as good: then the least effort (standing).
    score = np.where(forbidden, -np.inf, np.minimum(least, config.personal_space + COMFORT) - 0.02 * effort)
    if band is not None and len(band):
        ends = np.c_[px[:, -1], py[:, -1]]
        b = np.asarray(band, dtype=float).reshape(-1, 2)
        gap_to_band = np.hypot(ends[:, None, 0] - b[None, :, 0], ends[:, None, 1] - b[None, :, 1]).min(axis=1)
        score = score - BAND_WEIGHT * np.maximum(band_clearance - gap_to_band, 0.0)
    if previous is not None and 0 <= previous < len(score):
        score[previous] += KEEP_BONUS
    best = int(np.argmax(score))
    if stop_at[best] <= 0:
        return GiveWayMove(np.zeros(3), "stand", float(least[best]), best)
    return GiveWayMove(np.array([seqs[best, 0, 0], 0.0, seqs[best, 0, 1]]), names[best], float(least[best]), best)
