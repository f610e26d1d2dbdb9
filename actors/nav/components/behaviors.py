"""``Behaviors``: Nav2's behavior server. Recovery moves as event / fallback actions and as
action servers: ``spin``, ``backup``, ``drive_on_heading``, ``wait``, and ``clear_costmaps``
(the LocalMapper's ``clear_entirely_local_costmap`` service); and ``give_way`` to a person.

    behaviors = Behaviors(component_name="behaviors")
    Event(stuck_event, Action(method=behaviors.back_up, kwargs={"distance": 0.3}))
    Fallback ladder: [Action(method=behaviors.clear_costmaps), Action(method=behaviors.spin), ...]

Every move is planned by :mod:`emos.actors.nav.recovery` with the robot's footprint over the
whole motion against the latest scan (and the local grid when wired: it remembers what the scan
no longer sees, behind the robot included), and planned again on every step from the pose the
odometry gives, so an obstacle that appears mid-way stops it. A move that cannot be done is
refused with the reason (the component's status says it too: ALGORITHM failure naming the
behavior), e.g. ``back_up refused: obstacle 0.12 m behind``. Commands go to ``robot_command``
(wire it to a DriveManager command input of a higher priority than the Controller's,
``stacks.BEHAVIORS_COMMAND``, to keep its safety zones in the loop, or to the base directly as
Nav2 does).

Give way (``BehaviorsConfig(give_way=GiveWayConfig(enabled=True))``): the component tracks the
moving obstacles in its scan (``controllers.movers.MoverWatch``, the scan tracker the movers
Controller uses) and, when one is on a collision course (``recovery.GiveWayConfig``), takes the
robot over on its command input, above the Controller's: it stands short of the person, or backs
out of a passage / pulls aside when the person heads at it (``recovery.plan_give_way``, planned
again every step), until no mover has been on a collision course for ``clear_time`` s. With the
``static_map``, a mover whose straight line runs into a wall is also judged turning along it,
either way (``WallFilter.turns``: the tracker's velocity lags a person turning a corner). Then it
stops publishing and the Controller (and the mission) go on where they were.

Passage guard (``BehaviorsConfig(passage_guard=PassageGuardConfig(enabled=True))`` and the
Planner's ``plan`` wired as an input): the component remembers where the tracked movers walked
(``missions.passages.MoverMemory``: the band) and holds the robot (``hold_passage``, on the
same command input) *before* the stretch of its path that lies in the band while it could not
drive through it and out before a mover arrives (``missions.passages.check_passage``: the
movers predicted at constant velocity and as movers walked on from there before; the robot's
drive through predicted at the speed and start delay its odometry showed lately,
``missions.passages.DriveSpeed``, not a nominal speed a loaded machine does not reach). A person
walking a doorway cannot be given way to inside it; the robot waits outside their way instead,
and a mover walking where earlier walks went clear of it (round the corner of their walk before
reaching it) is not given way to there (``PassageGuardConfig.known_walks``).
With the ``people`` output wired (to the Planner's ``people`` input, ``PlannerConfig.people``)
the band is published once a second as an OccupancyGrid, and the Planner's routes cross it
rather than follow it (:mod:`emos.actors.nav.costmap.people`).
"""
from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from typing import Any, ClassVar

import attrs
import numpy as np
from attrs import define, field

from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.geometry import wrap_angle
from emos.msgs.srv import TriggerRequest, TriggerResponse

from .. import recovery as R
from ..controllers.movers import Approach, MoverWatch, WallFilter, approaches, near_movers, static_map_path
from ..controllers.sensors import obstacle_points
from ..costmap.people import BAND_RESOLUTION, band_grid
from ..missions.passages import DriveSpeed, MoverMemory, PassageGuardConfig, PassageVerdict, check_passage, walks_past
from .base import NavComponentConfig, rate_field
from .convert import BadInput, grid_msg, grid_points_in_robot_frame, path_of, scan_of, velocity_of
from .mission_interfaces import BackUpGoal, BehaviorFeedback, BehaviorResult, DriveOnHeadingGoal, SpinGoal, WaitGoal
from .motion_actions import MotionActionServer

__all__ = ["Behaviors", "BehaviorsConfig"]

MOVER_PAD = 0.15  # m: scan and grid points this near a tracked mover's circle are the mover (not static)
BAND_PERIOD = 1.0  # s between the band's publications (the Planner re-plans at 1 Hz)
HOLD_HYSTERESIS = 0.5  # m: a hold goes on while the band is this much farther than ``approach``
SPARED_EPISODE_GAP = 1.0  # s: give-ways not started this far apart are counted (and logged) once


def _give_way_config(value: Any) -> R.GiveWayConfig:
    if isinstance(value, R.GiveWayConfig):
        return value
    if isinstance(value, Mapping):
        return R.GiveWayConfig(**value)
    raise TypeError(f"BehaviorsConfig.give_way: expected a GiveWayConfig or a dict of its fields, got {type(value).__name__}")


def _passage_guard_config(value: Any) -> PassageGuardConfig:
    if isinstance(value, PassageGuardConfig):
        return value
    if isinstance(value, Mapping):
        return PassageGuardConfig(**value)
    raise TypeError(f"BehaviorsConfig.passage_guard: expected a PassageGuardConfig or a dict of its fields, got {type(value).__name__}")


@define(kw_only=True)
class BehaviorsConfig(NavComponentConfig):
    """Nav2's behavior server parameters where they are the same: ``max_rotational_vel`` (rad/s
    of a spin), ``safety_margin`` (m the footprint keeps from obstacles over a move),
    ``sensor_timeout`` (s: an older scan refuses every move), ``local_mapper`` (the component
    whose grid ``clear_costmaps`` clears). ``give_way``: when and how to give way to a moving
    obstacle (``recovery.GiveWayConfig``; off unless ``enabled``). ``passage_guard``: when to wait
    before the movers' way (``missions.passages.PassageGuardConfig``; off unless ``enabled``,
    needs the ``plan`` input). ``static_map`` (a map_server YAML in the frame of the ``location``
    input; the navigation stack gives its own map): a tracked "mover" whose centre lies within
    ``static_map_clearance`` m of the map's walls is a piece of wall the robot's motion smeared,
    not a person, and starts no give-way and no passage hold (``controllers.movers.WallFilter``;
    0 m: off)."""

    loop_rate: float = rate_field(10.0)
    max_rotational_vel: float = field(default=0.5, validator=in_range(min_value=1e-3, max_value=10.0))
    safety_margin: float = field(default=0.03, validator=in_range(min_value=0.0, max_value=1.0))
    sensor_timeout: float = field(default=1.0, validator=in_range(min_value=1e-3, max_value=1e3))
    local_mapper: str = field(default="mapper")
    xy_tolerance: float = field(default=0.01, validator=in_range(min_value=1e-4, max_value=1.0))
    yaw_tolerance: float = field(default=math.radians(1.0), validator=in_range(min_value=1e-4, max_value=1.0))
    give_way: R.GiveWayConfig = field(factory=R.GiveWayConfig, converter=_give_way_config)
    passage_guard: PassageGuardConfig = field(factory=PassageGuardConfig, converter=_passage_guard_config)
    static_map: str = field(default="", validator=static_map_path)
    static_map_clearance: float = field(default=0.1, validator=in_range(min_value=0.0, max_value=1.0))


@attrs.define
class _Running:
    name: str
    target: float  # rad of a spin, m of a drive, s of a wait
    speed: float
    start_pose: np.ndarray | None
    started: float  # node clock
    deadline: float
    done_amount: float = 0.0
    last_yaw: float = 0.0
    result: BehaviorResult | None = None
    stopped: bool = False  # the zero command after the end was sent (a cancel ends it off the loop)
    last_threat: float = 0.0  # give_way: node time a mover was last on a collision course
    move: str = ""  # give_way: the yield move of the last step
    move_index: int | None = None  # give_way: its candidate index (kept while nearly as good)
    overdue: bool = False  # hold_passage: past max_hold, holding on for a mover
    clear_since: float | None = None  # hold_passage: node time the verdicts turned clear (None: holding)


class Behaviors(MotionActionServer):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        **MotionActionServer.allowed_inputs, "local_map": AllowedTopic(types=("OccupancyGrid",), default=None),
        "plan": AllowedTopic(types=("Path",), default=None)}
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        **MotionActionServer.allowed_outputs,
        # The passage guard's band (where movers walked) for the Planner's people layer.
        "people": AllowedTopic(types=("OccupancyGrid",), default=None)}
    ACTIONS = tuple((name, goal, BehaviorFeedback, BehaviorResult, "_serve") for name, goal in
                    (("spin", SpinGoal), ("backup", BackUpGoal), ("drive_on_heading", DriveOnHeadingGoal), ("wait", WaitGoal)))
    config: BehaviorsConfig

    @classmethod
    def config_class(cls) -> type[BehaviorsConfig]:
        return BehaviorsConfig

    def custom_on_configure(self) -> None:
        self._lock = threading.Lock()
        self._running: _Running | None = None
        self._last: BehaviorResult | None = None
        self._counts = {"started": 0, "succeeded": 0, "refused": 0, "stopped": 0, "give_way": 0, "give_way_s": 0,
                        "passage_hold": 0, "passage_hold_s": 0, "passage_hold_given_up": 0, "known_walks_spared": 0}
        self._spared_at = -math.inf  # node time a give-way was last not started for a mover on a known walk
        self._give_way_time = 0.0  # s spent giving way (node clock)
        self._hold_time = 0.0  # s held before a passage (node clock)
        self._memory = MoverMemory(self.config.passage_guard.memory, band_memory=self.config.passage_guard.band_memory)
        self._drive_speed = DriveSpeed()  # how fast the robot really drives (the guard's drive through)
        self._no_hold_until = -math.inf  # node time: after a hold gave up, let the robot go through first
        self._entering = False  # the robot is at the band's edge and the guard lets it in (logged once)
        self._unseen_waited = False  # at this band edge the robot waited unseen_wait s for a mover to come into view
        self._movers = MoverWatch(walls=WallFilter.from_map_file(self.config.static_map, self.config.static_map_clearance))
        self._watched_scan: Any = None  # the scan message last fed to the mover tracker
        self._band_published = (-math.inf, -math.inf)  # (node time of the last people message, its last sample's time)
        if self.config.give_way.enabled:  # its first plan pays imports (~1 s here): not when a person is coming
            R.plan_give_way(self.config.robot, np.full((2000, 2), 10.0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0),
                            self.config.give_way, max_omega=self.config.max_rotational_vel)
        if self.get_out_topic("people") is not None and not self.config.passage_guard.enabled:
            raise ValueError(f"{self.component_name}: the 'people' output publishes the passage guard's band: give "
                             f"BehaviorsConfig(passage_guard=PassageGuardConfig(enabled=True))")
        self._create_action_servers()

    # -- what the robot sees ------------------------------------------------------------------------
    def _obstacles(self) -> tuple[np.ndarray, bool]:
        """Obstacle points in the robot frame and whether anything sees behind the robot.
        Raises BadInput (naming the topic) when the scan is missing or old."""
        msg = self.latest("sensor_data")
        age = self.age_of("sensor_data")
        if msg is None:
            raise BadInput(f"no scan on {self.topic_name('sensor_data')} yet")
        if not self.config.use_sim_time and age is not None and age > self.config.sensor_timeout:
            raise BadInput(f"{self.topic_name('sensor_data')} is stale: last scan {age:.2f} s ago")
        scan = scan_of(msg)
        pts = obstacle_points(scan)
        rear = R.scan_covers_rear(scan)
        grid = self.latest("local_map")
        if grid is not None:
            origin_frame = grid.header.frame_id
            pose = np.zeros(3) if origin_frame == self.config.frames.robot_base else self._pose()
            if pose is not None:
                cells = grid_points_in_robot_frame(grid, pose, max_range=2.0)
                pts = np.vstack([pts, cells]) if cells.size else pts
                rear = True  # the grid remembers what the scan saw before it turned away
        return pts, rear

    def _plan(self, run: _Running, remaining: float) -> R.BehaviorPlan:
        dt = 1.0 / self.config.loop_rate
        if run.name == "wait":
            return R.plan_wait(max(remaining, 1e-3), dt=dt)
        pts, rear = self._obstacles()
        m = self.config.safety_margin
        robot = self.config.robot
        if run.name == "spin":
            return R.plan_spin(robot, pts, math.copysign(remaining, run.target), max_omega=run.speed, dt=dt, margin=m)
        if run.name == "back_up":
            return R.plan_back_up(robot, pts, remaining, speed=run.speed, dt=dt, margin=m, rear_seen=rear)
        return R.plan_drive_on_heading(robot, pts, remaining, speed=run.speed, dt=dt, margin=m)

    # -- starting and playing -----------------------------------------------------------------------
    def _begin(self, name: str, target: float, speed: float, time_allowance: float, preempt: bool = False,
               why: str = "") -> tuple[bool, str]:
        """Check the whole move now and start it; (False, why) when refused. A fallback ladder
        fires its actions again while the failure lasts: a request for the behavior already
        running lets it go on, one for another is refused while it runs (an action goal,
        ``preempt``, replaces it, as in Nav2)."""
        with self._lock:
            busy = self._running if self._running is not None and self._running.result is None else None
        if busy is not None and not preempt:
            if busy.name == name:
                return True, f"{name} already running"
            return self._refuse(name, f"{name} refused: {busy.name} is running")
        now = clock.now()
        pose = self._pose()
        if name != "wait" and pose is None:
            return self._refuse(name, f"{name} refused: no pose on {self.topic_name('location')}")
        run = _Running(name, float(target), float(speed), pose, now, now + float(time_allowance),
                       last_yaw=float(pose[2]) if pose is not None else 0.0)
        if name in ("give_way", "hold_passage"):  # standing is always possible: each step picks the move
            run.last_threat = now
        else:
            try:
                plan = self._plan(run, abs(run.target))
            except (BadInput, ValueError) as exc:
                return self._refuse(name, f"{name} refused: {exc}")
            if not plan.feasible:
                return self._refuse(name, plan.reason)
        self._counts["started"] += 1
        if name in ("give_way", "hold_passage"):
            self._counts["give_way" if name == "give_way" else "passage_hold"] += 1
        preempted = None
        with self._lock:
            if self._running is not None and self._running.result is None:
                preempted = self._running.name
                self._running.result = BehaviorResult(success=False, message=f"{preempted} preempted by {name}")
            self._running = run
        if preempted is not None:
            self.get_logger().info("[%s] %s preempted by %s", self.component_name, preempted, name)
        self.get_logger().info("[%s] %s started (%.3g)%s", self.component_name, name, target, f": {why}" if why else "")
        return True, f"{name} started"

    def _refuse(self, name: str, reason: str) -> tuple[bool, str]:
        self._counts["refused"] += 1
        self.fail_algorithm(name, reason)
        self._last = BehaviorResult(success=False, message=reason)
        return False, reason

    def _finish(self, run: _Running, success: bool, message: str) -> None:
        self._stop_robot()
        run.stopped = True
        run.result = BehaviorResult(success=success, message=message, total_elapsed_time=clock.now() - run.started)
        self._last = run.result
        self._counts["succeeded" if success else "stopped"] += 1
        if run.name == "give_way":
            self._give_way_time += clock.now() - run.started
            self._counts["give_way_s"] = int(round(self._give_way_time))
        if run.name == "hold_passage":
            self._hold_time += clock.now() - run.started
            self._counts["passage_hold_s"] = int(round(self._hold_time))
        if success:
            self.health_status.set_healthy()
            self.get_logger().info("[%s] %s", self.component_name, message)
        else:
            self.fail_algorithm(run.name, message)

    def _execution_step(self, **kwargs: Any) -> None:
        with self._lock:
            ended = self._running if self._running is not None and self._running.result is not None else None
            run = self._running if self._running is not None and self._running.result is None else None
        if ended is not None and not ended.stopped:  # cancelled or preempted from another thread
            self._stop_robot()
            ended.stopped = True
        self._watch_movers()
        if self.config.passage_guard.enabled:
            pose = self._pose()
            if pose is not None:
                self._drive_speed.observe(clock.now(), float(pose[0]), float(pose[1]), driving=run is None)
        if self.config.give_way.enabled and (run is None or run.name != "give_way"):
            threat = self._threat()
            if threat is not None and self._begin("give_way", self.config.give_way.time_allowance, self.config.give_way.speed,
                                                  self.config.give_way.time_allowance, preempt=True, why=threat)[0]:
                with self._lock:
                    run = self._running
        if run is not None and run.name == "give_way":
            self._step_give_way(run)
            return
        if self.config.passage_guard.enabled and (run is None or run.name == "hold_passage"):
            verdict = self._passage_verdict(run)
            if run is None and verdict is not None and verdict.hold and clock.now() >= self._no_hold_until:
                guard = self.config.passage_guard
                if self._begin("hold_passage", guard.max_hold, 0.0, guard.max_hold, why=verdict.reason)[0]:
                    with self._lock:
                        run = self._running
            if run is not None and run.name == "hold_passage":
                self._step_hold(run, verdict)
                return
        if run is None:
            if self._last is None or self._last.success:
                self.health_status.set_healthy()
            return
        now = clock.now()
        if now > run.deadline:
            self._finish(run, False, f"{run.name} stopped: time allowance of {run.deadline - run.started:.1f} s used up "
                                     f"({run.done_amount:.2f} of {abs(run.target):.2f} done)")
            return
        if run.name == "wait":
            run.done_amount = now - run.started
        else:
            pose = self._pose()
            if pose is None or run.start_pose is None:
                self._finish(run, False, f"{run.name} stopped: lost the pose on {self.topic_name('location')}")
                return
            if run.name == "spin":
                run.done_amount += abs(wrap_angle(pose[2] - run.last_yaw))
                run.last_yaw = float(pose[2])
            else:
                run.done_amount = float(math.dist(pose[:2], run.start_pose[:2]))
        remaining = abs(run.target) - run.done_amount
        tol = self.config.yaw_tolerance if run.name == "spin" else (1e-3 if run.name == "wait" else self.config.xy_tolerance)
        if remaining <= tol:
            self._finish(run, True, f"{run.name} done: {run.done_amount:.2f} {'rad' if run.name == 'spin' else 's' if run.name == 'wait' else 'm'}")
            return
        try:
            plan = self._plan(run, remaining)
        except (BadInput, ValueError) as exc:
            self._finish(run, False, f"{run.name} stopped after {run.done_amount:.2f}: {exc}")
            return
        if not plan.feasible:
            self._finish(run, False, f"{run.name} stopped after {run.done_amount:.2f} of {abs(run.target):.2f}: {plan.reason}")
            return
        self._drive(plan.commands[0])

    # -- giving way to a moving obstacle ----------------------------------------------------------------
    def _watch_movers(self) -> None:
        """Feed a new scan to the mover tracker, at the pose odometry gives now."""
        msg = self.latest("sensor_data")
        if msg is None or msg is self._watched_scan:
            return
        pose = self._pose()
        if pose is None:
            return
        try:
            scan = scan_of(msg)
        except BadInput:
            return  # reported where the scan is used for a move
        self._watched_scan = msg
        stamp = msg.header.stamp.to_sec() if msg.header.stamp is not None else clock.now()
        last, restarts = self._movers.stamp, self._movers.restarts
        odom = self.latest("location")
        odom_stamp = getattr(getattr(odom, "header", None), "stamp", None)  # a Pose has none: no rewind then
        self._movers.update(stamp, obstacle_points(scan), pose, float(scan.angle_increment or 0.0),
                            pose_stamp=odom_stamp.to_sec() if odom_stamp is not None else None, twist=velocity_of(odom))
        if self._movers.restarts != restarts:  # the clock went back (a restarted simulator)
            self.get_logger().warning("[%s] %s: scan stamp %.2f s is %.2f s before the last one: the clock went back, "
                                      "mover tracking starts again", self.component_name, self.topic_name("sensor_data"),
                                      stamp, (last or 0.0) - stamp)
        if self.config.passage_guard.enabled:  # the band: where the movers walked, on the node clock the guard asks at
            centres, velocities, _ = self._movers.movers()
            self._memory.observe(clock.now(), centres, velocities)
            self._publish_band()

    def _publish_band(self) -> None:
        """The band on the ``people`` output (when wired), at most once per ``BAND_PERIOD`` s and
        only when a mover was recorded since."""
        out = self.get_out_topic("people")
        samples = self._memory.samples()
        if out is None or not len(samples):
            return
        now, newest = clock.now(), float(samples[-1, 0])
        if newest == self._band_published[1] or 0.0 <= now - self._band_published[0] < BAND_PERIOD:
            return
        self._band_published = (now, newest)
        data, origin = band_grid(self._memory.band_cells())
        self.publish(out, grid_msg(data, BAND_RESOLUTION, origin, self.config.frames.world))

    def _robot_velocity(self, pose: np.ndarray, standing: bool = False) -> np.ndarray:
        """The robot's velocity (world frame) from its odometry; zero when judged ``standing``."""
        body = None if standing else velocity_of(self.latest("location"))
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.zeros(2) if body is None else np.array([c * body[0] - s * body[1], s * body[0] + c * body[1]])

    def _approaches(self, pose: np.ndarray, standing: bool = False) -> list[Approach]:
        """Every tracked mover within ``detection_range``, relative to the robot moving at its
        odometry's velocity (world frame), or standing where it is (``standing``)."""
        cfg = self.config.give_way
        centres, velocities, radii = self._movers.movers()
        if len(centres) == 0:
            return []
        v = self._robot_velocity(pose, standing)
        return [a for a in approaches(pose[:2], v, self.config.robot.radius, centres, velocities, radii, cfg.time_before_collision)
                if a.gap_now <= cfg.detection_range]

    def _threat(self, pose: np.ndarray | None = None, standing: bool = False) -> str | None:
        """Why a mover is on a collision course with the robot (see ``GiveWayConfig``); None if none is.
        ``standing``: judged as if the robot stopped where it is, which it does when a give-way
        hands back; a yield move still under way must not count as the way being clear."""
        cfg = self.config.give_way
        pose = self._pose() if pose is None else pose
        if pose is None:
            return None
        centres, velocities, radii = self._movers.movers()
        guard = self.config.passage_guard
        # A robot that really stands (not one judged as if it stood, mid give-way) is not pushed
        # away by a mover that comes near on a known walk either: a person turning at the end of
        # their walk beside a robot waiting there, as every earlier walk turned clear of it.
        stands = not standing and float(np.hypot(*self._robot_velocity(pose))) < DriveSpeed.MOVING
        for a in self._approaches(pose, standing):
            coming = a.gap_min < cfg.personal_space and a.closing > 0.05
            near = a.gap_now < cfg.near_distance and a.closing > -0.05
            if (coming or near) and (stands or not near) and guard.enabled and guard.known_walks and walks_past(
                    self._memory, clock.now(), centres[a.index], velocities[a.index], pose[:2], self._robot_velocity(pose, standing),
                    self.config.robot.radius + float(radii[a.index]) + cfg.personal_space, cfg.time_before_collision, guard):
                if clock.now() - self._spared_at > SPARED_EPISODE_GAP:
                    self._counts["known_walks_spared"] += 1
                    x, y = centres[a.index]
                    self.get_logger().info("[%s] give_way not started: mover at (%.2f, %.2f) %.2f m away %s, but walks where "
                                           "earlier walks went, all of which kept clear of it", self.component_name, x, y, a.gap_now,
                                           "is near the standing robot" if near else "heads at the robot in a straight line")
                self._spared_at = clock.now()
                continue
            if coming or near:
                x, y = centres[a.index]
                return (f"mover at ({x:.2f}, {y:.2f}) {a.gap_now:.2f} m away, closing at {a.closing:.2f} m/s"
                        + (f", predicted within {max(a.gap_min, 0.0):.2f} m in {a.time_to_min:.1f} s" if coming else ""))
            turning = self._turn_threat(pose, standing, centres[a.index], velocities[a.index], float(radii[a.index]))
            if turning is not None:
                return turning
        return None

    def _turn_threat(self, pose: np.ndarray, standing: bool, centre: np.ndarray, velocity: np.ndarray, radius: float) -> str | None:
        """Why a mover whose straight line runs into a wall of the static map is on a collision
        course once it turns along the wall (either way, ``WallFilter.turns``): within
        ``personal_space`` of the robot within ``time_before_collision`` s, closer than it is now.
        None when not, with no map, or when earlier walks from here the same way are remembered
        (they say where it goes: the known-walks rule judges it)."""
        walls = self._movers.walls
        if walls is None:
            return None
        cfg, guard = self.config.give_way, self.config.passage_guard
        times = np.arange(0.0, cfg.time_before_collision + 1e-9, 0.1)
        ways = walls.turns(centre, velocity, radius, times)
        if not ways or len(self._memory.predict(clock.now(), centre, velocity, times[:2], match_distance=guard.match_distance,
                                                match_heading=guard.match_heading)) > 1:
            return None
        robot = pose[:2] + self._robot_velocity(pose, standing) * times[:, None]
        for way in ways:
            gap = np.hypot(*(way - robot).T) - self.config.robot.radius - radius
            k = int(np.argmin(gap))
            if gap[k] < cfg.personal_space and gap[k] < gap[0] - 0.05:
                return (f"mover at ({centre[0]:.2f}, {centre[1]:.2f}) {gap[0]:.2f} m away walks into a wall: turning along it "
                        f"at ({way[k][0]:.2f}, {way[k][1]:.2f}) it comes within {max(gap[k], 0.0):.2f} m in {times[k]:.1f} s")
        return None

    # -- waiting before the movers' way ------------------------------------------------------------------
    def _passage_verdict(self, run: _Running | None = None) -> PassageVerdict | None:
        """The passage guard's verdict now (None: no plan or pose to judge by). While a hold
        runs, judged from where it began: a robot that stopped a little into the band (the
        command's latency) is still before the stretch, not in it."""
        msg, pose = self.latest("plan"), self._pose()
        guard = self.config.passage_guard
        if run is not None and run.start_pose is not None:
            # Held from where the hold began, and on while the band is a little farther than
            # ``approach`` (a new plan moves its start by centimetres: no stop-and-go).
            pose = run.start_pose
            guard = attrs.evolve(guard, approach=guard.approach + HOLD_HYSTERESIS)
        if msg is None or pose is None:
            return None
        try:
            path = path_of(msg)
        except BadInput:
            return None
        if len(path) < 2:
            return None
        centres, velocities, radii = self._movers.movers()
        # Let go (not held): the drive through began at the release, or is under way already.
        under_way = run is None and float(np.hypot(*self._robot_velocity(pose))) >= DriveSpeed.MOVING
        let_go = self._drive_speed.since_release(clock.now()) if run is None else None
        verdict = check_passage(path, pose[:2], self._memory, clock.now(), centres, velocities, radii,
                                self.config.robot.radius, guard, measured_speed=self._drive_speed.speed(),
                                measured_delay=self._drive_speed.start_delay(), under_way=under_way, let_go=let_go,
                                walls=self._movers.walls)
        at_edge = verdict.start is not None and verdict.start <= guard.approach
        if not at_edge:
            self._unseen_waited = False
        elif verdict.unseen and guard.unseen_wait > 0 and not self._unseen_waited:
            # Nobody in view: wait (once per way in) for one of the band's people to come into view.
            waited = run.done_amount if run is not None and run.name == "hold_passage" else 0.0
            if waited >= guard.unseen_wait:
                self._unseen_waited = True
                verdict = attrs.evolve(verdict, reason=f"no mover came into view within unseen_wait ({guard.unseen_wait:.0f} s)")
            else:
                verdict = attrs.evolve(verdict, hold=True, reason=f"no mover in view or seen within out_of_view: waiting up to "
                                                                  f"{guard.unseen_wait:.0f} s for one to come into view")
        if at_edge and not verdict.hold and not self._entering:  # once per way in: why it went (the patrol's logs)
            seen = ", ".join(f"({c[0]:.2f}, {c[1]:.2f}) at ({v[0]:.2f}, {v[1]:.2f}) m/s" for c, v in zip(centres, velocities))
            self.get_logger().info("[%s] passage guard: into the band stretch %.2f-%.2f m ahead: %s; movers in view: %s",
                                   self.component_name, verdict.start, verdict.end, verdict.reason, seen or "none")
        self._entering = at_edge and not verdict.hold
        return verdict

    def _step_hold(self, run: _Running, verdict: PassageVerdict | None) -> None:
        """One step of holding before the band stretch: done when the guard has not said hold for
        ``release_time`` s. After ``max_hold`` s a wait for an unseen person gives up (and lets the
        robot go through), and so does one for a mover out of view whose walk from there is not
        known, the moment it has just left the view walking away (``PassageVerdict.just_left``);
        any other hold for a mover goes on until the way has been clear for ``release_time``:
        giving up whatever the verdict let the robot in while a person came back, and going on
        the first clear verdict let it in as one turned round."""
        now = clock.now()
        run.done_amount = now - run.started
        if verdict is not None and verdict.hold:
            run.last_threat = now
            if run.clear_since is not None:  # a clear spell cut short: why (the "into" line said why it began)
                self.get_logger().info("[%s] hold_passage held again after %.1f s clear: %s", self.component_name,
                                       now - run.clear_since, verdict.reason)
            run.clear_since = None
        elif run.clear_since is None:
            run.clear_since = now
        if verdict is None or now - run.last_threat >= self.config.passage_guard.release_time:
            self._finish(run, True, f"hold_passage done after {run.done_amount:.1f} s: "
                                    f"{verdict.reason if verdict is not None else 'no plan or pose to judge by'}")
            pose = self._pose()
            if pose is not None:  # how long the robot takes to start after a hold: the next drive through's delay
                self._drive_speed.released(now, float(pose[0]), float(pose[1]))
            return
        if now > run.deadline and verdict.hold and (verdict.unseen or verdict.just_left):
            self._no_hold_until = now + 3.0 * self.config.passage_guard.start_delay + 10.0
            self._counts["passage_hold_given_up"] += 1
            why = "; it just left the view walking away" if verdict.just_left else ""
            self._finish(run, False, f"hold_passage gave up after {run.done_amount:.1f} s (max_hold): {verdict.reason}{why}")
            return
        if now > run.deadline and not run.overdue:  # once per hold: why it goes on past max_hold
            run.overdue = True
            self.get_logger().info("[%s] hold_passage holds on past max_hold (%.0f s): %s", self.component_name,
                                   self.config.passage_guard.max_hold, verdict.reason)
        self._stop_robot()

    def _step_give_way(self, run: _Running) -> None:
        """One step of giving way: done when no mover has been on a collision course for
        ``clear_time`` s; else the best yield move now (``recovery.plan_give_way``)."""
        cfg = self.config.give_way
        now = clock.now()
        pose = self._pose()
        if pose is None or run.start_pose is None:
            self._finish(run, False, f"give_way stopped: lost the pose on {self.topic_name('location')}")
            return
        run.done_amount = now - run.started
        threat = self._threat(pose, standing=True)
        if threat is not None:
            run.last_threat = now
        moved = float(math.dist(pose[:2], run.start_pose[:2]))
        if now - run.last_threat >= cfg.clear_time:
            self._finish(run, True, f"give_way done: the way is clear ({run.done_amount:.1f} s, moved {moved:.2f} m)")
            return
        if now > run.deadline:
            self._finish(run, False, f"give_way stopped: a mover still on a collision course after {cfg.time_allowance:g} s "
                                     f"(time_allowance; moved {moved:.2f} m)")
            return
        try:
            pts, _ = self._obstacles()
        except BadInput as exc:
            self._finish(run, False, f"give_way stopped: {exc}")
            return
        centres, velocities, radii = self._movers.movers()
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rel = centres - pose[:2]
        local = np.c_[c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]
        local_v = np.c_[c * velocities[:, 0] + s * velocities[:, 1], -s * velocities[:, 0] + c * velocities[:, 1]]
        static = pts[~near_movers(pts, local, radii, MOVER_PAD)] if len(pts) else pts
        band = None
        if self.config.passage_guard.enabled:  # where the movers walk: a yield move should not end in it
            cells = self._memory.lasting_band_cells(now) - pose[:2]
            cells = cells[np.hypot(cells[:, 0], cells[:, 1]) < 3.0]
            band = np.c_[c * cells[:, 0] + s * cells[:, 1], -s * cells[:, 0] + c * cells[:, 1]]
        dt = 1.0 / self.config.loop_rate
        futures, future_radii = self._other_ways(pose, centres, velocities, radii, R.give_way_times(cfg, dt))
        move = R.plan_give_way(self.config.robot, static, local, local_v, radii, cfg, max_omega=self.config.max_rotational_vel,
                               dt=dt, margin=self.config.safety_margin, previous=run.move_index,
                               band=band, band_clearance=self.config.passage_guard.band_clearance,
                               futures=futures, future_radii=future_radii)
        if move.name != run.move:
            self.get_logger().info("[%s] give_way: %s (least predicted gap %.2f m)%s", self.component_name, move.name, move.gap,
                                   f": {threat}" if threat else "")
        run.move, run.move_index = move.name, move.index
        self._drive(move.command)

    def _other_ways(self, pose: np.ndarray, centres: np.ndarray, velocities: np.ndarray, radii: np.ndarray,
                    times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the movers may go other than straight on, in the robot frame at ``times`` s:
        as earlier walks from where each is went on (the passage guard's memory), or, with none
        remembered, turning along a wall its straight line runs into (``WallFilter.turns``).
        (P, len(times), 2) points and (P,) radii; none when neither applies."""
        ways: list[np.ndarray] = []
        owners: list[float] = []
        guard = self.config.passage_guard
        for centre, velocity, radius in zip(centres, velocities, radii):
            learned = (self._memory.predict(clock.now(), centre, velocity, times, match_distance=guard.match_distance,
                                            match_heading=guard.match_heading)[1:] if guard.enabled else [])
            if not learned and self._movers.walls is not None:
                learned = self._movers.walls.turns(centre, velocity, float(radius), times)
            ways.extend(learned)
            owners.extend([float(radius)] * len(learned))
        if not ways:
            return np.zeros((0, len(times), 2)), np.zeros(0)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rel = np.asarray(ways, dtype=float) - pose[:2]
        local = np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]], axis=-1)
        return local, np.asarray(owners)

    # -- actions (events, fallbacks) ------------------------------------------------------------------
    def spin(self, angle: float = math.pi / 2, time_allowance: float = 30.0) -> bool:
        """Turn in place by ``angle`` rad, if the footprint stays clear over the whole turn."""
        return self._begin("spin", angle, self.config.max_rotational_vel, time_allowance)[0]

    def back_up(self, distance: float = 0.3, speed: float = 0.1, time_allowance: float = 30.0) -> bool:
        """Drive straight back ``distance`` m, if what is behind is seen and clear."""
        return self._begin("back_up", distance, speed, time_allowance)[0]

    def drive_on_heading(self, distance: float = 0.3, speed: float = 0.1, time_allowance: float = 30.0) -> bool:
        return self._begin("drive_on_heading", distance, speed, time_allowance)[0]

    def wait(self, duration: float = 1.0) -> bool:
        return self._begin("wait", duration, 0.0, duration + 5.0)[0]

    def give_way(self, time_allowance: float | None = None) -> bool:
        """Give way now (an event action): stand, back out or pull aside until no tracked mover
        has been on a collision course for ``give_way.clear_time`` s (at most ``time_allowance``
        s, default ``give_way.time_allowance``). With ``give_way.enabled`` this starts by itself."""
        cfg = self.config.give_way
        allowance = cfg.time_allowance if time_allowance is None else float(time_allowance)
        return self._begin("give_way", allowance, cfg.speed, allowance, preempt=True, why="asked")[0]

    def clear_costmaps(self) -> bool:
        """Clear the LocalMapper's grid (its ``clear_entirely_local_costmap`` service)."""
        from emos.core.services import ServiceClient

        name = f"{self.config.local_mapper}/clear_entirely_local_costmap"
        try:
            client = ServiceClient(name, TriggerRequest, TriggerResponse, ctx=self.node.ctx, timeout=5.0)
            try:
                answer = client.call(TriggerRequest())
            finally:
                client.close()
        except Exception as exc:  # noqa: BLE001 - reported: the service may be down
            self._refuse("clear_costmaps", f"clear_costmaps failed: service {name}: {type(exc).__name__}: {exc}")
            return False
        self.get_logger().info("[%s] clear_costmaps: %s", self.component_name, answer.message)
        return bool(answer.success)

    def stats(self) -> dict[str, int]:
        """How many behaviors started, succeeded, were refused or stopped (a mission's report);
        ``give_way``: how many of the starts gave way to a mover, ``give_way_s``: for how long (s);
        ``passage_hold``: how many held the robot before the movers' way, ``passage_hold_s``: for
        how long (s), ``passage_hold_given_up``: how many of those ended at ``max_hold``;
        ``known_walks_spared``: how many times a give-way was not started for a mover walking
        where earlier walks went clear of the robot (``PassageGuardConfig.known_walks``);
        ``movers_on_walls``: tracks left out as pieces of the static map's walls (once per scan each)."""
        return {**self._counts, "movers_on_walls": self._movers.left_out}

    @property
    def last_result(self) -> BehaviorResult | None:
        return self._last

    # -- action servers ---------------------------------------------------------------------------------
    def _serve(self, handle: Any) -> BehaviorResult:
        goal = handle.goal
        if isinstance(goal, SpinGoal):
            ok, why = self._begin("spin", goal.target_yaw, self.config.max_rotational_vel, goal.time_allowance, preempt=True)
        elif isinstance(goal, BackUpGoal):
            ok, why = self._begin("back_up", goal.distance, goal.speed, goal.time_allowance, preempt=True)
        elif isinstance(goal, DriveOnHeadingGoal):
            ok, why = self._begin("drive_on_heading", goal.distance, goal.speed, goal.time_allowance, preempt=True)
        else:
            ok, why = self._begin("wait", goal.time, 0.0, goal.time + 5.0, preempt=True)
        if not ok:
            return BehaviorResult(success=False, message=why)
        with self._lock:
            run = self._running
        assert run is not None

        def cancel() -> None:
            if run.result is None:
                run.result = BehaviorResult(success=False, message=f"{run.name} cancelled")

        return self._follow_goal(handle, lambda: run.result, cancel=cancel, feedback=lambda: BehaviorFeedback(
            behavior=run.name, progress=min(1.0, run.done_amount / max(abs(run.target), 1e-9))))
