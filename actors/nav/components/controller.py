"""``Controller``: follows the global plan (or a vision target) with any algorithm of
:data:`~emos.actors.nav.controllers.registry.CONTROLLERS`, chosen by ``ControllersID``.

Obstacles come straight from the scanner (``direct_sensor`` True: ``sensor_data``, a LaserScan
or a PointCloud2) or from the LocalMapper's grid (False: ``local_map``). Both inputs are
subscribed when they have topics, so ``use_direct_sensor`` can be switched at run time (an
event action may do it when the mapper fails). Run types: Timed (follow the latest ``plan``)
or ActionServer (``ControlPath``: follow a given path until it is reached or cancelled); with a
``vision_tracking``/``vision_detections`` input, a ``<name>/track_vision_target`` action too.
No path, no valid trajectory or a blocked robot is reported as an ALGORITHM failure; a missing
or stale input as a SYSTEM failure, and the robot is then sent a zero command.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import attrs
import numpy as np
from attrs import define, field

from emos.config.validators import in_, in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs.control import TwistArray
from emos.msgs.geometry import Twist, TwistStamped
from emos.msgs.sensor import LaserScan
from emos.msgs.std import Header

from ..controllers import ControllersID, ControlResult, ControlStatus
from ..controllers.clearance import warm_up as clearance_warm_up
from ..controllers.follower import PathFollower
from ..controllers.registry import CONTROLLERS, make_controller
from ..controllers.sensors import LaserScan2D, obstacle_points
from ..costmap.config import mask_path
from ..costmap.filters import KeepoutObstacles, SpeedFilter, load_filter_mask
from ..kinematics import integrate
from ..stuck import ProgressChecker, StallHold
from .base import NavComponent, NavComponentConfig, rate_field
from .controller_vision import VisionTracking
from .convert import BadInput, grid2d_of, grid_points_in_robot_frame, path_msg, path_of, points_of, scan_of, twist_msg
from .interfaces import ControlPathFeedback, ControlPathGoal, ControlPathResult

__all__ = ["Controller", "ControllerConfig"]

_FAILURES = (ControlStatus.BLOCKED, ControlStatus.NO_PATH, ControlStatus.LOST)


def _algorithm(value: Any) -> str:
    return ControllersID.from_any(value).value


@define(kw_only=True)
class ControllerConfig(NavComponentConfig):
    """``algorithm``: a ``ControllersID`` (or its name). ``control_time_step`` (s) between the
    commands of a computed sequence. ``ctrl_publish_type``: "Sequence" (each command on
    ``command`` in its time step), "Array" (the whole sequence on ``multi_command``) or
    "Parallel" (both). ``use_direct_sensor``: obstacles from ``sensor_data`` (True) or
    ``local_map`` (False). ``sensor_timeout`` / ``location_timeout`` (s): older inputs stop the robot.
    ``progress_timeout`` (s, 0: off): less than ``progress_distance`` m of progress along the plan
    in that time is a stall, reported as an ALGORITHM failure ("no progress") that holds until
    the robot has moved 0.1 m (for the recipe's fallbacks: back out, block the plan's tightest
    spot). ``failure_tolerance`` (s): a blocked or path-less step is reported as an ALGORITHM
    failure only once such steps have lasted this long (0: at once; Nav2's parameter).
    Point clouds: only points between ``cloud_min_height`` (above the floor) and
    ``cloud_max_height`` (default: the robot's height) are obstacles.
    ``pose_prediction`` (s, 0: off): with obstacles in ``frames.world`` (a ``local_map`` in the
    world frame, placed by its own origin), a step plans from where the robot is now: the
    location's pose carried forward over its age (now minus its stamp, when that is between 0
    and this many seconds) with its measured twist. A localizer's pose is as old as the scan it
    matched, and lags the robot by the mapping time (in lock-step, where the controller may
    run before the mapper has taken the tick's scan, a scan and a half: 30 ms, 6 cm at 2 m/s).
    ``world_map_range`` (m): how far around the robot a world-frame ``local_map`` is read (beyond
    every built-in algorithm's reach at 2 m/s). ``speed_mask``: a speed filter mask (Nav2's speed
    filter; ``emos map zones``): inside its zones commands are scaled down to the zone's limit.
    ``keepout_mask``: a keepout filter mask (in ``frames.world``): the edges of its zones within
    ``world_map_range`` are obstacles to every algorithm, whatever the obstacle input, so the
    robot is not driven into a zone by a plan that crosses one (a planner without the mask, a
    path sent from outside) or by the algorithm's own detours (:class:`KeepoutObstacles`)."""

    loop_rate: float = rate_field(10.0)
    algorithm: str = field(default=ControllersID.DWA.value, converter=_algorithm, on_setattr=attrs.setters.convert)
    control_time_step: float = field(default=0.1, validator=in_range(min_value=1e-3, max_value=10.0))
    ctrl_publish_type: str = field(default="Sequence", validator=in_(("Sequence", "Array", "Parallel")))
    use_direct_sensor: bool = field(default=True)
    sensor_timeout: float = field(default=0.5, validator=in_range(min_value=1e-3, max_value=1e3))
    location_timeout: float = field(default=0.5, validator=in_range(min_value=1e-3, max_value=1e3))
    cloud_min_height: float = field(default=0.05, validator=in_range(min_value=-100.0, max_value=100.0))
    cloud_max_height: float | None = field(default=None)
    progress_timeout: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1e4))
    progress_distance: float = field(default=0.3, validator=in_range(min_value=1e-3, max_value=100.0))
    failure_tolerance: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1e4))
    pose_prediction: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=1.0))
    world_map_range: float = field(default=5.0, validator=in_range(min_value=0.1, max_value=1e4))
    speed_mask: str = field(default="", validator=mask_path("speed"))
    keepout_mask: str = field(default="", validator=mask_path("keepout"))


class Controller(VisionTracking, NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "plan": AllowedTopic(types=("Path",), default=Topic(name="/plan", msg_type="Path")),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry"), required=True),
        "sensor_data": AllowedTopic(types=("LaserScan", "PointCloud2"), default=Topic(name="/scan", msg_type="LaserScan")),
        "local_map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/local_map/occupancy_layer", msg_type="OccupancyGrid")),
        "vision_tracking": AllowedTopic(types=("Trackings", "Detections")),
        "vision_detections": AllowedTopic(types=("Detections", "Trackings")),
        "depth_camera_info": AllowedTopic(types=("CameraInfo",)),
        "depth_image": AllowedTopic(types=("Image",)),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/control", msg_type="Twist")),
        "multi_command": AllowedTopic(types=("TwistArray",), default=Topic(name="/control_list", msg_type="TwistArray")),
        "interpolation": AllowedTopic(types=("Path",), default=Topic(name="/interpolated_path", msg_type="Path")),
        "local_plan": AllowedTopic(types=("Path",), default=Topic(name="/local_path", msg_type="Path")),
        "tracked_point": AllowedTopic(types=("PoseStamped", "Odometry", "Pose", "Detections"), default=Topic(name="/tracked_point", msg_type="PoseStamped")),
    }
    main_action_type = (ControlPathGoal, ControlPathFeedback, ControlPathResult)
    config: ControllerConfig
    # Step state, set by custom_on_configure (set_algorithm tells a running controller from a
    # configured-only one by whether _progress exists yet, so they get no class default).
    _stall: StallHold
    _progress: ProgressChecker | None
    _failing_since: float | None

    def __init__(self, component_name: str, config: ControllerConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        self._algorithms_config: Any = None

    @classmethod
    def config_class(cls) -> type[ControllerConfig]:
        return ControllerConfig

    # -- recipe API --------------------------------------------------------------------------------------
    @property
    def algorithm(self) -> ControllersID:
        return ControllersID.from_any(self.config.algorithm)

    @algorithm.setter
    def algorithm(self, value: ControllersID | str) -> None:
        self.config.algorithm = value

    plugin = algorithm  # the name the spec's usage example uses

    def action_servers(self) -> dict[str, tuple[Any, Any, Any]]:
        servers = super().action_servers()
        servers.update(self.vision_action_servers())
        return servers

    def set_algorithm(self, algorithm: ControllersID | str) -> bool:
        """Switch the control algorithm (an event or fallback action); the next step uses it.
        The previous algorithm's failure (a stall held until the robot moves, a blocked streak)
        is cleared: the new one has not failed yet, and a fallback ladder that switched must
        judge it by its own steps, not by its predecessor's report."""
        previous = self.config.algorithm
        self.config.algorithm = algorithm
        if self.config.algorithm != previous and self._node is not None and hasattr(self, "_progress"):  # running
            self._stall.clear()
            self._failing_since = None
            if self._progress is not None:
                self._progress.reset()
            if self.health_status.is_algorithm_fail:
                self.health_status.set_healthy()
            self.get_logger().info("[%s] algorithm switched from %s to %s", self.component_name, previous, self.config.algorithm)
        return True

    @property
    def direct_sensor(self) -> bool:
        return self.config.use_direct_sensor

    @direct_sensor.setter
    def direct_sensor(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise TypeError(f"component {self.component_name!r}: direct_sensor must be True or False, got {value!r}")
        self.config.use_direct_sensor = value

    @property
    def algorithms_config(self) -> Any:
        return self._algorithms_config

    @algorithms_config.setter
    def algorithms_config(self, value: Any) -> None:
        """The algorithm's own config (``DWAConfig``, ``VisionRGBFollowerConfig``, ...)."""
        known = {cfg_cls: cid for cid, (_, cfg_cls) in CONTROLLERS.items()}
        if type(value) not in known:
            raise TypeError(f"component {self.component_name!r}: algorithms_config must be one of "
                            f"{', '.join(c.__name__ for c in known)}, got {type(value).__name__}")
        self._algorithms_config = value

    # -- lifecycle --------------------------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        self.default_trigger("sensor_data" if self.config.use_direct_sensor else "local_map")
        self._follower: Any = None
        self._follower_id: str | None = None
        self._plan_stamp: Any = None
        self._finished_stamp: Any = None
        self._sequence: tuple[np.ndarray, int] | None = None
        self._speed_filter = SpeedFilter(load_filter_mask(self.config.speed_mask, "speed")) if self.config.speed_mask else None
        self._keepout = KeepoutObstacles(load_filter_mask(self.config.keepout_mask, "keepout")) if self.config.keepout_mask else None
        self._last_cmd = np.zeros(3)
        self._action_active = False
        self._failing_since = None
        self._stall = StallHold(release=0.1)  # a reported stall holds until the robot has moved 0.1 m
        cfg = self.config
        self._progress = ProgressChecker(cfg.progress_timeout, cfg.progress_distance) if cfg.progress_timeout > 0 else None
        self.configure_vision()
        # The followers' k-d tree (scipy, a fraction of a second to seconds of CPU to import) is
        # imported here, not when the first step with a plan builds the follower: that step then
        # judged its inputs by the wall clock after the import, found /odom "stale" whenever the
        # import took more than location_timeout (a busy machine), and a SYSTEM failure restarted
        # the controller, whose new process imported it in its first step again.
        clearance_warm_up()

    def custom_on_activate(self) -> None:
        if self.config.ctrl_publish_type != "Array":
            # Later commands of a computed sequence go out in their own time steps.
            self.create_timer(self.config.control_time_step, self._sequence_tick)

    def _make_follower(self) -> Any:
        cid = self.algorithm
        if self._follower is None or self._follower_id != cid.value:
            cfg = self._algorithms_config if isinstance(self._algorithms_config, CONTROLLERS[cid][1]) else None
            if cfg is None:
                cfg = CONTROLLERS[cid][1]()
                if hasattr(cfg, "control_time_step"):
                    cfg.control_time_step = self.config.control_time_step
            self._follower = make_controller(cid, self.config.robot, cfg)
            self._follower_id = cid.value
            self._plan_stamp = None  # a new follower has no path yet
        return self._follower

    # -- inputs ------------------------------------------------------------------------------------------
    def obstacles(self, pose: np.ndarray | None = None) -> Any:
        """The obstacle input of this step (robot frame), or raise BadInput naming the topic.

        A ``local_map`` in ``frames.world`` (an obstacle memory, a map) rather than ego-centric
        is placed by its own origin and brought into the frame of the robot at ``pose``."""
        key = "sensor_data" if self.config.use_direct_sensor else "local_map"
        topic = self.get_in_topic(key)
        if topic is None:
            raise BadInput(f"{key}: no topic (use_direct_sensor={self.config.use_direct_sensor})")
        msg = self.get_input(topic)
        age = self.input_age(topic)
        if msg is None:
            raise BadInput(f"no message on {topic.name} yet")
        if age is not None and age > self.config.sensor_timeout:
            raise BadInput(f"{topic.name} is stale: last message {age:.2f} s ago")
        self._source_stamp = msg.header.stamp  # a TwistStamped command carries its data's time
        if key == "local_map":
            if self.world_frame_obstacles(msg) and pose is not None:
                return grid_points_in_robot_frame(msg, pose, self.config.world_map_range), key
            return grid2d_of(msg), key
        if isinstance(msg, LaserScan):
            return scan_of(msg), key
        pts = points_of(msg)
        top = self.config.cloud_max_height if self.config.cloud_max_height is not None else self.config.robot.height
        return pts[(pts[:, 2] >= self.config.cloud_min_height) & (pts[:, 2] <= top)], key

    def world_frame_obstacles(self, msg: Any) -> bool:
        """True when ``msg`` (the local_map input) is in the world frame, not ego-centric."""
        return bool(msg.header.frame_id) and msg.header.frame_id == self.config.frames.world

    def predicted_pose(self, pose: np.ndarray, velocity: np.ndarray | None) -> np.ndarray:
        """``pose`` (the location's) carried forward to now with ``velocity`` (see
        ``ControllerConfig.pose_prediction``); unchanged when its age is unknown or out of range."""
        horizon = self.config.pose_prediction
        msg = self.latest("location")
        if horizon <= 0.0 or velocity is None or msg is None or not hasattr(msg, "header"):
            return pose
        age = clock.now() - msg.header.stamp.to_sec()
        if not 0.0 < age <= horizon:
            return pose  # no age on our clock (another clock, a stamp from the future): as it is
        return integrate(pose, velocity, age)

    def _movers_scan(self) -> Any:
        """The scan an algorithm that tracks moving obstacles follows them in, when its obstacles
        come from the local map; raise BadInput naming the topic."""
        topic = self.get_in_topic("sensor_data")
        if topic is None:
            raise BadInput(f"{self.algorithm.value} tracks moving obstacles in the scan: give the sensor_data input "
                           "a LaserScan topic")
        msg = self.get_input(topic)
        age = self.input_age(topic)
        if msg is None:
            raise BadInput(f"no message on {topic.name} yet (moving obstacles are tracked in it)")
        if not isinstance(msg, LaserScan):
            raise BadInput(f"{topic.name}: moving obstacles are tracked in a LaserScan, got {type(msg).__name__}")
        if age is not None and age > self.config.sensor_timeout:
            raise BadInput(f"{topic.name} is stale: last message {age:.2f} s ago")
        return scan_of(msg)

    # -- path following ----------------------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        if self._action_active or self.tracking_active:
            return  # an action drives the robot now
        plan = self.latest("plan")
        if plan is None or len(plan.poses) == 0:
            # Nothing to follow: hold the robot; the health keeps the last report (a failed
            # action stays visible to fallbacks until the controller has something new to do).
            self.publish_stop()
            return
        stamp = (plan.header.stamp.sec, plan.header.stamp.nanosec, len(plan.poses))
        if stamp == self._finished_stamp:
            # This plan is done: hold the robot (a fresh zero command, so the DriveManager
            # sees a live controller) until a new plan arrives.
            self.publish_stop()
            self.health_status.set_healthy()
            return
        result = self.follow(plan, stamp)
        if result is not None and result.status is ControlStatus.GOAL_REACHED:
            self._finished_stamp = stamp

    def follow(self, plan: Any, stamp: Any) -> ControlResult | None:
        """One control step along ``plan``; publishes the commands; None on missing input."""
        follower = self._make_follower()
        if self.algorithm in (ControllersID.VISION_IMG, ControllersID.VISION_DEPTH):
            self.fail_algorithm(self.algorithm.value, "a vision follower tracks targets (track_vision_target action), not paths")
            self.publish_stop()
            return None
        state = self.robot_state(self.config.location_timeout)
        if state is None:
            self.publish_stop()
            return None
        pose, velocity = state
        map_topic = None if self.config.use_direct_sensor else self.get_in_topic("local_map")
        if map_topic is not None:
            local_map = self.get_input(map_topic)
            if local_map is not None and self.world_frame_obstacles(local_map):
                # Obstacles placed by their own origin do not move with the pose: plan from where
                # the robot is now, not from where the localizer last saw it.
                pose = self.predicted_pose(pose, velocity)
        velocity = self._last_cmd if velocity is None else velocity
        try:
            obstacles, key = self.obstacles(pose)
        except BadInput as exc:
            self.fail_input("sensor_data" if self.config.use_direct_sensor else "local_map", str(exc))
            self.publish_stop()
            return None
        if stamp != self._plan_stamp:
            try:
                follower.set_path(path_of(plan))
            except (BadInput, ValueError) as exc:
                self.fail_input("plan", str(exc))
                self.publish_stop()
                return None
            self._plan_stamp = stamp
            out = self.get_out_topic("interpolation")
            if out is not None:
                self.publish(out, path_msg(follower.path.poses()[:: max(1, len(follower.path) // 500)], self.config.frames.world))
        follower.sensor_pose = (0.0, 0.0, 0.0) if key == "local_map" else tuple(follower.scan_pose)
        extra = {}
        if key == "local_map" and follower.tracks_movers:
            # A grid has no beam order: the algorithm tracks moving obstacles in the scan.
            try:
                extra["scan"] = self._movers_scan()
            except BadInput as exc:
                self.fail_input("sensor_data", str(exc))
                self.publish_stop()
                return None
        obstacles = self._with_keepout(obstacles, pose, follower, extra)
        result = follower.compute(pose, velocity, obstacles, **extra)
        self.publish_result(result)
        self._report_step(result, pose, follower)
        return result

    def _with_keepout(self, obstacles: Any, pose: np.ndarray, follower: PathFollower, extra: dict[str, Any]) -> Any:
        """The step's obstacles with the keepout zones' edges near the robot added (as points in
        the robot frame; ``follower.sensor_pose`` is then the robot's own)."""
        if self._keepout is None:
            return obstacles
        edges, inside = self._keepout.around(pose, self.config.world_map_range, clear=self.config.robot.radius)
        if inside is not None:
            self._report.warning("keepout:inside", "[%s] the robot is inside keepout zone %s: the zone is not kept out "
                                 "of until the robot has left it", self.component_name, inside, logger=self.get_logger())
        if not len(edges):
            return obstacles
        if isinstance(obstacles, LaserScan2D) and follower.tracks_movers and "scan" not in extra:
            extra["scan"] = obstacles  # movers are tracked in the scan's beam order, which points lose
        points = obstacle_points(obstacles, follower.sensor_pose)
        follower.sensor_pose = (0.0, 0.0, 0.0)
        return np.vstack([points, edges])

    def _report_step(self, result: ControlResult, pose: np.ndarray, follower: PathFollower) -> None:
        """Health after one step: failures (after ``failure_tolerance``), stalls (the progress
        checker), else healthy."""
        now = clock.now()
        failing = result.status in _FAILURES
        self._failing_since = (self._failing_since if self._failing_since is not None else now) if failing else None
        progress = follower.progress
        # Standing aside or slowing for a moving obstacle nearby is waiting, not a stall.
        waiting = follower.waiting
        if self._progress is not None and (progress is None or result.status is ControlStatus.GOAL_REACHED or waiting):
            self._progress.reset()
        elif self._progress is not None and progress is not None and self._progress.update(now, float(progress.remaining)):
            self._stall.hold(pose[:2])
            self.fail_algorithm(self.algorithm.value, f"no progress: {self._progress.describe()} "
                                f"({progress.remaining:.2f} m of plan left)")
            self.node.publish_status()  # at once: fallbacks act on it
            return
        if self._stall.holding(pose[:2]):
            return  # the stall holds until a recovery has moved the robot
        # failing implies _failing_since is set (just above); the None check only narrows the type.
        if failing and self._failing_since is not None and now - self._failing_since >= self.config.failure_tolerance:
            self.fail_algorithm(self.algorithm.value, f"{result.status.value}: no valid trajectory" if result.status is ControlStatus.BLOCKED else result.status.value)
        else:
            self.health_status.set_healthy()

    # -- publishing ---------------------------------------------------------------------------------------
    def publish_result(self, result: ControlResult) -> None:
        cmds = self._speed_capped(np.asarray(result.commands, dtype=np.float64).reshape(-1, 3))
        kind = self.config.ctrl_publish_type
        if kind in ("Sequence", "Parallel"):
            self._publish_command(cmds[0])
            self._sequence = (cmds, 1) if len(cmds) > 1 else None
        if kind in ("Array", "Parallel"):
            out = self.get_out_topic("multi_command")
            if out is not None:
                lin = np.zeros((len(cmds), 3))
                ang = np.zeros((len(cmds), 3))
                lin[:, :2], ang[:, 2] = cmds[:, :2], cmds[:, 2]
                self.publish(out, TwistArray(linear_velocities=lin, angular_velocities=ang))
        self._last_cmd = cmds[0]
        local = self.get_out_topic("local_plan")
        if local is not None and len(result.local_plan):
            self.publish(local, path_msg(np.asarray(result.local_plan).reshape(-1, 3), self.config.frames.world))

    def _speed_capped(self, cmds: np.ndarray) -> np.ndarray:
        """Inside a zone of ``speed_mask`` (at the robot's location, in the mask's map frame), each
        command whose linear speed is above the zone's limit is scaled down whole, keeping its curvature."""
        state = self.robot_state()
        if self._speed_filter is None or state is None:
            return cmds
        return self._speed_filter.capped(cmds, state[0][:2], self.config.robot.ctrl_vx_limits.max_vel)

    def _publish_command(self, cmd: np.ndarray) -> None:
        out = self.get_out_topic("command")
        if out is None:
            return
        msg: Twist | TwistStamped = twist_msg(cmd)
        if out.msg_type is TwistStamped:
            # Stamped with the time of the sensor data it was computed from (its age downstream).
            stamp = getattr(self, "_source_stamp", None) or clock.stamp()
            msg = TwistStamped(header=Header(stamp=stamp, frame_id=self.config.frames.robot_base), twist=msg)
        self.publish(out, msg)

    def publish_stop(self) -> None:
        self._sequence = None
        self._last_cmd = np.zeros(3)
        self._publish_command(np.zeros(3))

    def _sequence_tick(self) -> None:
        if self._sequence is None:
            return
        cmds, i = self._sequence
        if i >= len(cmds) or i * self.config.control_time_step >= 1.0 / self.config.loop_rate:
            self._sequence = None  # the next step computes a fresh sequence
            return
        self._publish_command(cmds[i])
        self._last_cmd = cmds[i]
        self._sequence = (cmds, i + 1)

    # -- ControlPath action -------------------------------------------------------------------------------
    def _main_action_callback(self, goal_handle: Any) -> ControlPathResult:
        goal: ControlPathGoal = goal_handle.goal
        given = goal.path if len(goal.path.poses) else None
        pacer = self.node.pacer(1.0 / self.config.loop_rate)  # on the node's clock; inside its ticks on simulated time
        self._action_active = True
        failing_since: float | None = None
        try:
            while True:
                if goal_handle.is_cancel_requested:
                    self.publish_stop()
                    return ControlPathResult(success=False, message="cancelled")
                plan = given if given is not None else self.latest("plan")
                if plan is None or len(plan.poses) == 0:
                    self.publish_stop()
                    pacer.wait(lambda: goal_handle.is_cancel_requested)
                    continue
                stamp = "goal" if given is not None else (plan.header.stamp.sec, plan.header.stamp.nanosec, len(plan.poses))
                result = self.follow(plan, stamp)
                self.node.publish_status()
                if result is not None:
                    left = self._follower.progress.remaining if self._follower.progress is not None else math.nan
                    goal_handle.publish_feedback(ControlPathFeedback(distance_left=float(left), status=result.status.value))
                    if result.status is ControlStatus.GOAL_REACHED:
                        self.publish_stop()
                        return ControlPathResult(success=True, message="goal reached")
                    # On the node's clock: 10 simulated seconds under a simulator, however slow it runs.
                    if result.status not in _FAILURES:
                        failing_since = None
                    elif failing_since is None:  # not `or`: simulated time starts at 0.0
                        failing_since = clock.now()
                    if failing_since is not None and clock.now() - failing_since > 10.0:
                        self.publish_stop()
                        return ControlPathResult(success=False, message=f"{result.status.value} for 10 s")
                pacer.wait(lambda: goal_handle.is_cancel_requested)
        finally:
            pacer.close()
            self._action_active = False
