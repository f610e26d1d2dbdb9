"""Time-indexed collision checks of sampled arcs against moving obstacles.

A tracker (``mapping/tracking.py``) gives each moving obstacle a centre, a constant velocity
and a radius. The arc planner (``arcs.py``) asks :meth:`PredictedMovers.clearances` for the
smallest gap between the robot's footprint at each arc sample, at that sample's *time*, and
every obstacle *predicted to that time*. The check goes on past the arc's horizon with the
robot standing at the arc's end for ``hold`` s: an arc is only safe if the robot can stop
after it and not be run into, so the planner never parks in a mover's way. The predicted
positions grow a margin with time (``margin_rate``: velocity uncertainty).

:class:`MoverWatch` is the same tracking for components that are not arc planners: the
DriveManager's swept check (``mover_prediction_time``: a mover's predicted trail counts as an
obstacle) and the ``Behaviors``' give-way (:func:`approaches`: who is on a collision course).
:class:`WallFilter` leaves out the tracks a static map says cannot be people (on its walls).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.config import validators as V

if TYPE_CHECKING:
    from ..mapping.tracking import TrackerConfig
    from ..maps.grid import OccupancyGridMap
    from .arcs import ArcPlanner

__all__ = ["Approach", "MoverConfig", "MoverWatch", "PredictedMovers", "PredictionConfig", "WallFilter", "approaches", "static_map_path",
           "near_movers", "rewind"]


@attrs.define(frozen=True)
class PredictionConfig:
    hold: float = attrs.field(default=1.0, validator=V.finite_non_negative)  # s standing at the arc's end, checked too
    hold_step: float = attrs.field(default=0.1, validator=V.finite_non_negative)  # s between the hold's samples
    margin: float = attrs.field(default=0.06, validator=V.finite_non_negative)  # m kept from a predicted mover
    margin_rate: float = attrs.field(default=0.1, validator=V.finite_non_negative)  # m per s of prediction
    safe_clearance: float = attrs.field(default=0.5, validator=V.finite_non_negative)  # closer to a mover costs extra
    weight: float = attrs.field(default=2.0, validator=V.finite_non_negative)  # cost per m inside safe_clearance


def _tracker_config(value: object) -> TrackerConfig:
    from ..mapping.tracking import TrackerConfig

    if isinstance(value, TrackerConfig):
        return value
    if isinstance(value, dict):
        return TrackerConfig(**value)
    raise TypeError(f"MoverConfig.tracker: expected a TrackerConfig or a dict, got {type(value).__name__}")


def _prediction_config(value: object) -> PredictionConfig:
    if isinstance(value, PredictionConfig):
        return value
    if isinstance(value, dict):
        return PredictionConfig(**value)
    raise TypeError(f"MoverConfig.prediction: expected a PredictionConfig or a dict, got {type(value).__name__}")


def _default_tracker() -> TrackerConfig:
    from ..mapping.tracking import TrackerConfig

    return TrackerConfig()


@attrs.define(frozen=True)
class MoverConfig:
    """Moving-obstacle handling for an arc planner: how scans are tracked (``mapping.tracking``)
    and how the tracks are predicted and checked (``PredictionConfig``). ``wait_radius`` (m):
    with a moving track this near, slow or no progress is waiting for it, not being stuck.
    ``footprint_pad`` (m): obstacle points within a moving track's circle plus this are the
    mover's own (a grid or memory that holds them is not asked about them as static)."""

    tracker: TrackerConfig = attrs.field(factory=_default_tracker, converter=_tracker_config)
    prediction: PredictionConfig = attrs.field(factory=PredictionConfig, converter=_prediction_config)
    wait_radius: float = attrs.field(default=3.0, validator=V.number(ge=0, finite=True, what="a finite number of metres"))
    footprint_pad: float = attrs.field(default=0.15, validator=V.number(ge=0, finite=True, what="a finite number of metres"))


def near_movers(xy: np.ndarray, centres: np.ndarray, radii: np.ndarray, pad: float) -> np.ndarray:
    """Per point (N, 2): within ``pad`` of a mover's circle (``centres`` (M, 2), ``radii`` (M,))."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(centres) == 0 or len(xy) == 0:
        return np.zeros(len(xy), dtype=bool)
    d = np.hypot(xy[:, None, 0] - centres[None, :, 0], xy[:, None, 1] - centres[None, :, 1])
    return np.any(d <= np.asarray(radii)[None, :] + pad, axis=1)


@attrs.define(frozen=True, eq=False)
class PredictedMovers:
    """Moving obstacles as circles at ``stamp``: ``centres`` (M, 2), ``velocities`` (M, 2) m/s,
    ``radii`` (M,) m, all in the planner's (world) frame."""

    centres: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1, 2))
    velocities: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1, 2))
    radii: np.ndarray = attrs.field(converter=lambda a: np.asarray(a, dtype=float).reshape(-1))
    config: PredictionConfig = attrs.field(factory=PredictionConfig)

    def __attrs_post_init__(self) -> None:
        if not (len(self.centres) == len(self.velocities) == len(self.radii)):
            raise ValueError(f"PredictedMovers: centres, velocities and radii must have one row per obstacle, got "
                             f"{len(self.centres)}, {len(self.velocities)}, {len(self.radii)}")

    def __len__(self) -> int:
        return len(self.centres)

    def clearances(self, planner: ArcPlanner, pose: np.ndarray, groups: list) -> np.ndarray:
        """Per arc (the planner's order): smallest footprint-to-mover gap over the arc and the
        hold after it, less the time-growing margin (m; <= 0 means predicted contact)."""
        cfg = self.config
        spec = planner.spec
        hx, hy, off = spec.length / 2, spec.width / 2, spec.center_offset
        x0, y0, th0 = (float(v) for v in pose)
        c0, s0 = math.cos(th0), math.sin(th0)
        # Movers in the start pose's frame.
        rel = self.centres - (x0, y0)
        mx = c0 * rel[:, 0] + s0 * rel[:, 1]
        my = -s0 * rel[:, 0] + c0 * rel[:, 1]
        vx = c0 * self.velocities[:, 0] + s0 * self.velocities[:, 1]
        vy = -s0 * self.velocities[:, 0] + c0 * self.velocities[:, 1]
        n_hold = int(round(cfg.hold / cfg.hold_step)) if cfg.hold > 0 and cfg.hold_step > 0 else 0
        out = []
        for (_v, _turns, dx, dy, ct, st, _wt, _reach), t in zip(groups, planner._times):
            if n_hold:
                horizon = float(t[-1])
                t = np.concatenate([t, horizon + cfg.hold_step * np.arange(1, n_hold + 1)])
                pad = lambda a: np.concatenate([a, np.repeat(a[:, -1:], n_hold, axis=1)], axis=1)  # noqa: E731
                dx, dy, ct, st = pad(dx), pad(dy), pad(ct), pad(st)
            # Mover positions at each sample time (samples, M), relative to each arc pose.
            px = mx[None, :] + vx[None, :] * t[:, None]
            py = my[None, :] + vy[None, :] * t[:, None]
            qx = px[None] - dx[..., None]
            qy = py[None] - dy[..., None]
            lx = ct[..., None] * qx + st[..., None] * qy - off
            ly = -st[..., None] * qx + ct[..., None] * qy
            # Box-to-centre gap (Chebyshev-like: never more than the true distance), less radius
            # and the margin grown over the prediction time.
            gap = np.maximum(np.abs(lx) - hx, np.abs(ly) - hy) - self.radii[None, None, :]
            gap = gap - (cfg.margin + cfg.margin_rate * t)[None, :, None]
            out.append(gap.min(axis=(1, 2)).astype(float))
        return np.concatenate(out)


# -- moving obstacles for the safety layer and the give-way behavior ---------------------------------

REWIND_MAX = 0.5  # s: the most a pose is carried back to its scan's time (an older pose is a stale input)


def rewind(pose: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
    """``pose`` (x, y, yaw) ``dt`` s earlier, the robot having moved at the body ``twist``
    (vx, vy, omega) meanwhile (an arc at constant twist, integrated backwards)."""
    x, y, yaw = (float(v) for v in pose[:3])
    vx, vy, w = (float(v) for v in twist[:3])
    yaw0 = yaw - w * dt
    mid = 0.5 * (yaw + yaw0)
    c, s = math.cos(mid), math.sin(mid)
    return np.array([x - (c * vx - s * vy) * dt, y - (s * vx + c * vy) * dt, yaw0])


def _to_world(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    return np.c_[pose[0] + c * points[:, 0] - s * points[:, 1], pose[1] + s * points[:, 0] + c * points[:, 1]]


def _to_robot(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rel = points - np.asarray(pose[:2], dtype=float)
    return np.c_[c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]


CLOCK_BACK_S = 1.0  # a scan this much older than the last one means the clock went back
# WallFilter.turns: a mover whose body would come within TURN_MARGIN m of a wall turns along it; a
# way that runs into a wall within TURN_CLEAR_TIME s of the turn is not one (the corner's other
# side); movers slower than TURN_MIN_SPEED m/s have no line to follow.
TURN_MARGIN = 0.05  # m
TURN_CLEAR_TIME = 0.5  # s
TURN_MIN_SPEED = 0.2  # m/s


def static_map_path(instance: Any, attribute: Any, value: Any) -> None:
    """attrs validator of a config's static map for the :class:`WallFilter` (a map_server YAML,
    '': none): loaded where it is set, so a bad one names its file at definition."""
    if not isinstance(value, str):
        raise TypeError(f"{type(instance).__name__}.{attribute.name}: expected a map YAML path (str), got {type(value).__name__}")
    if value:
        from ..maps import load_map

        load_map(value)


class WallFilter:
    """Tracks a static map says cannot be people. A robot's own motion smears the walls it scans
    (a pose a few centimetres off the scan's time), and the scan tracker then calls a piece of
    wall moving; such a "mover" sits on the wall, where a person cannot stand (a person's centre
    stays their body's half-width off it). Scan hits within ``clearance`` m of an occupied cell
    of ``grid`` (same frame as the tracks) are the wall's: :class:`MoverWatch` tracks the rest
    (so a person walking past a table the map has is not one cluster with it, standing still);
    a track whose centre, or most of whose last hits, lie that near is left out
    (:meth:`tracks_on_walls`). Measured in the patrol's
    house (20 laps): of the give-ways started for a mover more than 0.5 m off the person's walk,
    96 % were for one within 0.12 m of a wall; of those started for the person, 1 %. Off the map
    nothing is left out (the map does not know what is there)."""

    def __init__(self, grid: OccupancyGridMap, clearance: float = 0.1) -> None:
        from ..maps import distance_map

        if not (math.isfinite(clearance) and 0.0 <= clearance <= 1.0):
            raise ValueError(f"WallFilter: clearance must be in [0, 1] m, got {clearance!r}")
        self.grid = grid
        self.clearance = float(clearance)
        self.distance = distance_map(grid)  # m from each cell's centre to the nearest wall cell's (inf: none)

    @classmethod
    def from_map_file(cls, map_file: str, clearance: float) -> WallFilter | None:
        """The filter of a map_server YAML, or None when there is no file or ``clearance`` is 0 (off)."""
        if not map_file or clearance <= 0:
            return None
        from ..maps import load_map

        return cls(load_map(map_file), clearance)

    def on_walls(self, centres: np.ndarray) -> np.ndarray:
        """(M,) True where a point (M, 2), a track's centre or a scan hit, lies within
        ``clearance`` of a wall of the map."""
        return self.wall_distance(centres) <= self.clearance

    def tracks_on_walls(self, centres: np.ndarray, hits: list[np.ndarray]) -> np.ndarray:
        """(M,) True for a track whose centre (M, 2) is on a wall (:meth:`on_walls`) or whose
        last hits (M arrays (K, 2)) mostly are. The tracker puts a cluster's centre behind its
        hits, as if they were the front of a round thing (up to a third of a metre): for a
        piece of a thin wall that is past the wall. A person's hits are on their front, never
        mostly on a wall. Replayed on a recorded patrol (scripts/replay_tracker.py), the hits cut
        the scans with a mover that was not the person from 20 % to 3 % and kept every sighting
        of the person."""
        on = self.on_walls(centres)
        for i, pts in enumerate(hits):
            if not on[i] and len(pts):
                on[i] = bool(np.median(self.wall_distance(pts)) <= self.clearance)
        return on

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """(M,) m from each point (M, 2) to the nearest wall of the map (inf off the map: it does
        not know what is there)."""
        cells = self.grid.world_to_grid(np.asarray(points, dtype=float).reshape(-1, 2))
        inside = self.grid.in_bounds(cells)
        out = np.full(len(cells), np.inf)
        out[inside] = self.distance[cells[inside, 1], cells[inside, 0]]
        return out

    def turns(self, centre: np.ndarray, velocity: np.ndarray, radius: float, times: np.ndarray) -> list[np.ndarray]:
        """Where a mover goes whose straight line runs into a wall before ``times[-1]`` s: along
        the wall, either way, from where its body would touch it (a person does not walk through
        walls; at a corner they turn, and the tracker's velocity lags the turn by a second, so a
        person turning a corner towards the robot is predicted walking on into the wall until
        they are half-way to it). Positions (len(times), 2) at ``times`` (s from now) for each
        way that stays off the walls for ``TURN_CLEAR_TIME`` s after the turn (standing where it
        meets the next one); [] when the line stays clear, starts at a wall, or the mover walks
        slower than ``TURN_MIN_SPEED``."""
        c, v = np.asarray(centre, dtype=float)[:2], np.asarray(velocity, dtype=float)[:2]
        speed = float(np.hypot(*v))
        times = np.asarray(times, dtype=float)
        if speed < TURN_MIN_SPEED or len(times) < 2:
            return []
        line = c + v * times[:, None]
        touch = self.wall_distance(line) < radius + TURN_MARGIN
        if not touch.any() or touch[0]:
            return []
        k = int(np.argmax(touch)) - 1  # the last sample clear of the wall: where the turn is
        u = v / speed
        ways = []
        for side in (1.0, -1.0):
            along = np.array([-u[1], u[0]]) * side * speed
            way = np.where((times <= times[k])[:, None], line, line[k] + along * np.clip(times - times[k], 0.0, None)[:, None])
            blocked = np.flatnonzero((times > times[k]) & (self.wall_distance(way) < radius + TURN_MARGIN))
            if len(blocked):  # the next wall: it stops there (or turns again, unknown)
                j = int(blocked[0])
                if times[j] - times[k] <= TURN_CLEAR_TIME:
                    continue  # the corner's other side: no way there
                way[j:] = way[j - 1]
            ways.append(way)
        return ways


class MoverWatch:
    """The scan tracker (``mapping.tracking.ScanTracker``) fed one scan at a time in the robot
    frame with the pose it was taken at: the moving-obstacle view that the DriveManager's swept
    check and the ``Behaviors`` give-way share. Never ground truth: clusters of the scan.
    ``walls``: tracks on a static map's walls are not movers (:class:`WallFilter`);
    ``left_out`` counts them, once per scan each."""

    def __init__(self, tracker: TrackerConfig | None = None, walls: WallFilter | None = None) -> None:
        from ..mapping.tracking import ScanTracker

        self.tracker = ScanTracker(tracker)
        self.walls = walls
        self.left_out = 0
        self.stamp: float | None = None
        self.restarts = 0  # times the clock went back and tracking started again

    def update(self, stamp: float, points: np.ndarray, pose: np.ndarray, angle_increment: float = 0.0, *,
               pose_stamp: float | None = None, twist: np.ndarray | None = None) -> None:
        """Feed one scan: ``points`` (N, 2) in the robot frame, in beam order, taken at ``stamp`` s.
        ``pose`` (x, y, yaw, world frame) is the robot's at ``pose_stamp`` (default: the scan's);
        with the body ``twist`` (vx, vy, omega) it is carried back to the scan's time: a pose
        a tenth of a second newer than the scan, on a robot that turns, shifts a person 2 m
        away by centimetres from scan to scan, and such jitter keeps the tracker from calling
        the track moving. A scan older than the last one is ignored, unless it is older by more
        than ``CLOCK_BACK_S``: then the clock went back (a restarted simulator starts at 0), and
        tracking starts again rather than ignoring every scan until the clock catches up."""
        if self.stamp is not None and stamp < self.stamp - CLOCK_BACK_S:
            self.tracker = type(self.tracker)(self.tracker.cfg)
            self.stamp = None
            self.restarts += 1
        if self.stamp is not None and stamp <= self.stamp:
            return
        pose = np.asarray(pose, dtype=float)
        if pose_stamp is not None and twist is not None:
            pose = rewind(pose, np.asarray(twist, dtype=float), min(max(float(pose_stamp) - float(stamp), 0.0), REWIND_MAX))
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        world = _to_world(pts, pose)
        if self.walls is not None and len(world):
            world = world[~self.walls.on_walls(world)]  # the map's walls are no movers' hits
        self.tracker.update(float(stamp), world, pose[:2].copy(), float(angle_increment))
        self.stamp = float(stamp)
        if self.walls is not None:
            self.left_out += int(self._on_walls(self.tracker.moving_tracks(self.stamp)).sum())

    def _on_walls(self, tracks: list) -> np.ndarray:
        """(M,) True for each moving track of ``tracks`` that ``walls`` leaves out."""
        assert self.walls is not None and self.stamp is not None
        if not tracks:
            return np.zeros(0, dtype=bool)
        return self.walls.tracks_on_walls(np.array([t.predict(self.stamp) for t in tracks]), [t.points for t in tracks])

    def movers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centres (M, 2) now, velocities (M, 2) m/s, radii (M,) m), world frame, of the moving
        tracks (those on the walls of ``walls`` left out)."""
        if self.stamp is None:
            return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
        centres, velocities, radii = self.tracker.movers(self.stamp)
        if self.walls is not None and len(centres):
            keep = ~self._on_walls(self.tracker.moving_tracks(self.stamp))
            return centres[keep], velocities[keep], radii[keep]
        return centres, velocities, radii

    def trail_points(self, pose: np.ndarray, horizon: float, step: float = 0.1, per_circle: int = 16,
                     keep_clear: float = 0.0) -> np.ndarray:
        """Points (K, 2) in the frame of ``pose``: the outline of every moving track at each
        ``step`` of its constant-velocity prediction from now to ``horizon`` s. Added to a
        static check's obstacles they make the space a mover is about to walk into an obstacle
        now: a check that treats the scan as frozen (the DriveManager's swept footprint) then
        no longer lets the robot drive into where a person will be by the time it stops.

        A trail ends before its circle comes within ``keep_clear`` m (the robot's radius and a
        margin) of the robot's position: a person heading at the robot would walk into it there
        anyway, and a trail through and past the robot would stand on all its sides and forbid
        the one thing left, getting out of the way (the check lets the robot move away from
        what is already near, never over it)."""
        centres, velocities, radii = self.movers()
        if len(centres) == 0 or horizon <= 0:
            return np.zeros((0, 2))
        t = np.arange(0.0, horizon + 1e-9, max(step, 1e-3))
        ang = np.linspace(0.0, 2 * math.pi, per_circle, endpoint=False)
        ring = np.c_[np.cos(ang), np.sin(ang)]
        # (M, T, 2) predicted centres; each trail up to (not into) the robot; (K, per_circle, 2) outlines.
        c = centres[:, None, :] + velocities[:, None, :] * t[None, :, None]
        reach = np.hypot(c[..., 0] - pose[0], c[..., 1] - pose[1]) - radii[:, None]
        blocked = reach < keep_clear
        before = np.cumsum(blocked, axis=1) == 0
        before[:, 0] = True  # where it is now is in the scan anyway
        outline = c[before][:, None, :] + np.repeat(radii, before.sum(axis=1))[:, None, None] * ring[None, :, :]
        return _to_robot(outline.reshape(-1, 2), pose)

    def extend(self, points: np.ndarray, pose: np.ndarray | None, stamp: float, horizon: float,
               angle_increment: float = 0.0, *, pose_stamp: float | None = None, twist: np.ndarray | None = None,
               keep_clear: float = 0.0) -> np.ndarray:
        """Track this scan's ``points`` (robot frame, beam order; see :meth:`update` for the pose)
        and return them with the movers' predicted trails (:meth:`trail_points`) added; ``points``
        alone without a pose."""
        if pose is None:
            return points
        self.update(stamp, points, pose, angle_increment, pose_stamp=pose_stamp, twist=twist)
        trail = self.trail_points(pose, horizon, keep_clear=keep_clear)
        return np.vstack([points, trail]) if len(trail) else points


@attrs.define(frozen=True)
class Approach:
    """A mover relative to the robot: ``index`` (its row in the movers' arrays), ``gap_now`` and
    ``gap_min`` (m between the robot's circle and the mover's, now and the least over the
    horizon at constant velocities), ``time_to_min`` (s until that least gap), ``closing``
    (m/s: how fast the distance shrinks now; > 0 approaching)."""

    index: int
    gap_now: float
    gap_min: float
    time_to_min: float
    closing: float


def approaches(robot_xy: np.ndarray, robot_velocity: np.ndarray, robot_radius: float, centres: np.ndarray,
               velocities: np.ndarray, radii: np.ndarray, horizon: float) -> list[Approach]:
    """The closest approach of the robot (a circle at ``robot_xy`` moving at ``robot_velocity``,
    world frame) and each mover within ``horizon`` s, both at constant velocity."""
    out = []
    p = np.asarray(robot_xy, dtype=float)[:2]
    vr = np.asarray(robot_velocity, dtype=float)[:2]
    for i, (c, v, r) in enumerate(zip(np.asarray(centres, float).reshape(-1, 2), np.asarray(velocities, float).reshape(-1, 2),
                                      np.asarray(radii, float).reshape(-1))):
        d = c - p
        rv = v - vr
        dist = float(np.hypot(*d))
        speed2 = float(rv @ rv)
        t_min = 0.0 if speed2 < 1e-9 else min(max(-float(d @ rv) / speed2, 0.0), horizon)
        closest = float(np.hypot(*(d + rv * t_min)))
        closing = -float(d @ rv) / max(dist, 1e-9)
        reach = robot_radius + float(r)
        out.append(Approach(i, dist - reach, closest - reach, t_min, closing))
    return out
