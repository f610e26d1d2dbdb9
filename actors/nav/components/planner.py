"""``Planner``: global paths on the map, from the robot's location to a goal.

Run types (all four): Timed re-plans from the current location to the last goal every
``1/loop_rate`` s; Event plans when a goal arrives on ``goal_point``; Server answers
``PlanPath`` requests on ``<name>/service``; ActionServer takes a ``PlanPath`` goal (a pose and
an ``end_tolerance``, as in Kompass) on ``<name>/plan_path`` and keeps re-planning until the
robot is within the goal's tolerance (or ``distance_tolerance``) of it, or the goal is cancelled. The plan is published on ``plan`` and ``reached_end`` goes True
when the robot arrives. Plans can be saved, loaded and recorded (:mod:`.planner_paths`). A goal inside an obstacle, off the map or unreachable is an ALGORITHM
failure (the message says which); no map or no location is a SYSTEM failure naming the topic.

A goal on ``goal_point`` may also be a ``Detections`` or ``PointsOfInterest`` message with its depth
image (from a detector or VLM on an RGBD stream): it becomes a world goal through the camera
intrinsics (``depth_camera_info``), the transform tree (``tf``) and the location (:mod:`.pixel_goals`).

Planning runs on a worker thread, so a long query never stalls the component's heartbeat.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import math
import threading
import time
from collections.abc import Mapping
from typing import Any, ClassVar

import attrs
import numpy as np
from attrs import define, field

from emos.config.base import ComponentRunType
from emos.config.qos import TRANSIENT_LOCAL, QoSConfig
from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs.nav import Path
from emos.msgs.std import Bool, Header

from ..costmap import CostmapConfig, LayeredCostmap, PeopleLayerConfig, SmootherConfig, people_cost, smooth_path, walked_points
from ..paths import path_ahead
from ..planning import OMPLConfig
from ..planning.grid_planner import GRID_PLANNERS
from ..planning.interpolation import path_length
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, goal_of, grid_map_of, grid_msg, path_msg
from .interfaces import PlanPathFeedback, PlanPathGoal, PlanPathRequest, PlanPathResponse, PlanPathResult
from .pixel_goals import PIXEL_GOAL_TYPES, PixelGoals, is_pixel_goal
from .planner_paths import PathFiles
from .planners import check_planner_id, make_global_planner

__all__ = ["Planner", "PlannerConfig"]

#: a re-plan keeps the followed plan only while the robot is within this of it (m); farther
#: (pushed aside, or given way) the plan from where it is now is taken
KEPT_PLAN_MAX_OFFSET = 0.5
#: m closer to the goal along a kept plan that count as progress (``replan_stall_time``)
KEPT_PLAN_PROGRESS = 0.2


def _ompl(value: Any) -> OMPLConfig:
    if isinstance(value, OMPLConfig):
        return value
    if isinstance(value, dict):
        return OMPLConfig.from_dict(value)
    raise TypeError(f"PlannerConfig.ompl: expected an OMPLConfig or a mapping, got {type(value).__name__}")


def _nested(cls: type, value: Any) -> Any:
    if isinstance(value, dict):
        return cls(**value)
    if not isinstance(value, cls):
        raise TypeError(f"PlannerConfig: expected a {cls.__name__} or a mapping, got {type(value).__name__}")
    return value


def _costmap(value: Any) -> CostmapConfig:
    return _nested(CostmapConfig, value)


def _smoother(value: Any) -> SmootherConfig:
    return _nested(SmootherConfig, value)


def _people(value: Any) -> PeopleLayerConfig:
    return _nested(PeopleLayerConfig, value)


def _people_needs_a_grid_planner(instance: Any, attribute: Any, value: PeopleLayerConfig) -> None:
    if value.enabled and instance.planner_id not in GRID_PLANNERS:
        raise ValueError(f"PlannerConfig.people: the people layer is a cost on the grid planners' cells "
                         f"(planner_id one of {', '.join(GRID_PLANNERS)}), got planner_id {instance.planner_id!r}")


@define(kw_only=True)
class PlannerConfig(NavComponentConfig):
    """``planner_id``: an OMPL geometric planner (``"ompl.geometric.RRTConnect"``, ...) or a
    grid planner (``"CostToGo"``). ``ompl``: the OMPL settings (timeouts, thresholds, planner
    parameters). ``distance_tolerance`` (m): the robot counts as arrived within it.

    ``replan_min_gain``: OMPL's planners sample at random, so two plans to one goal differ (and a
    plan round a zone on the left may follow one round it on the right, turning the robot back
    and forth). Each re-plan towards the same goal therefore keeps the plan the robot is
    following while that is still free on the map and the robot is on it, unless the new plan
    is this fraction shorter than what is left of it; a re-plan that finds no path in time
    keeps it too. A kept plan is published again unchanged (its stamp too). 0: every re-plan
    replaces it. ``replan_stall_time`` (s): a plan along which the robot has not come 0.2 m
    closer to the goal in this long is not kept (a plan squeezing past a corner that the
    Controller cannot follow; 0: kept however the robot does). Grid planners are deterministic
    and always give their new plan (a people layer may change their costs)."""

    loop_rate: float = rate_field(1.0)
    planner_id: str = field(default="ompl.geometric.KPIECE1", validator=lambda i, a, v: check_planner_id(v))
    ompl: OMPLConfig = field(factory=OMPLConfig, converter=_ompl, on_setattr=attrs.setters.convert)
    distance_tolerance: float = field(default=0.15, validator=in_range(min_value=1e-3, max_value=100.0))
    planning_timeout: float = field(default=5.0, validator=in_range(min_value=1e-3, max_value=1e4))
    replan_min_gain: float = field(default=0.1, validator=in_range(min_value=0.0, max_value=1.0))
    replan_stall_time: float = field(default=10.0, validator=in_range(min_value=0.0, max_value=1e4))
    #: metres per unit of an integer (16UC1, mono16) depth image of a pixel goal; 32FC1 is metres
    depth_conversion_factor: float = field(default=1e-3, validator=in_range(min_value=1e-9, max_value=1e3))
    #: the global costmap (Nav2 names): used when enabled or given a mask; see emos.actors.nav.costmap
    costmap: CostmapConfig = field(factory=CostmapConfig, converter=_costmap, on_setattr=attrs.setters.convert)
    #: Nav2's simple smoother after each plan (enabled=True), collision-checked on the costmap
    smoother: SmootherConfig = field(factory=SmootherConfig, converter=_smoother, on_setattr=attrs.setters.convert)
    #: a soft cost where people walked (the ``people`` input, the Behaviors' band): CostToGo only;
    #: see emos.actors.nav.costmap.people
    people: PeopleLayerConfig = field(factory=PeopleLayerConfig, converter=_people, validator=_people_needs_a_grid_planner,
                                      on_setattr=[attrs.setters.convert, attrs.setters.validate])


class _MainInterface:
    """What ``ui_main_action_input`` names when the goal does not come from a topic."""

    def __init__(self, name: str, kind: str, types: tuple) -> None:
        self.name, self.kind, self.types = name, kind, types

    def __repr__(self) -> str:
        return f"{self.kind}({self.name!r}, {self.types[0].__name__})"


class Planner(PixelGoals, PathFiles, NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL)), required=True),
        "goal_point": AllowedTopic(types=("PointStamped", "PoseStamped", "Odometry") + PIXEL_GOAL_TYPES, default=Topic(name="/goal", msg_type="PointStamped")),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry"), required=True),
        # For goals in pixels (Detections, PointsOfInterest with their depth image): the camera's
        # intrinsics and the transform tree that places the camera on the robot.
        "depth_camera_info": AllowedTopic(types=("CameraInfo",), default=Topic(name="/camera/aligned_depth_to_color/camera_info", msg_type="CameraInfo")),
        "tf": AllowedTopic(types=("TFMessage",), default=Topic(name="/tf", msg_type="TFMessage")),
        # Where people walked (the Behaviors' ``people`` output), for the people layer.
        "people": AllowedTopic(types=("OccupancyGrid",), default=None),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "plan": AllowedTopic(types=("Path",), default=Topic(name="/plan", msg_type="Path"), required=True),
        "reached_end": AllowedTopic(types=("Bool",), default=Topic(name="/reached_end", msg_type="Bool")),
        "global_costmap": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/global_costmap/costmap", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL))),
    }
    main_srv_type = (PlanPathRequest, PlanPathResponse)
    main_action_type = (PlanPathGoal, PlanPathFeedback, PlanPathResult)
    config: PlannerConfig

    def __init__(self, component_name: str, config: PlannerConfig | None = None, **kwargs: Any) -> None:
        kwargs.setdefault("main_action_name", f"{component_name}/plan_path")  # Kompass' name
        super().__init__(component_name, config=config, **kwargs)

    @classmethod
    def config_class(cls) -> type[PlannerConfig]:
        return PlannerConfig

    @property
    def ui_main_action_input(self) -> Any:
        """Where a UI sends goals: the ``goal_point`` topic (Timed, Event), else the main
        service or action with its request type."""
        if self.run_type == ComponentRunType.SERVER:
            return _MainInterface(self.main_srv_name, "service", self.main_srv_type)
        if self.run_type == ComponentRunType.ACTION_SERVER:
            return _MainInterface(self.main_action_name, "action", self.main_action_type)
        return self.get_in_topic("goal_point")

    # -- lifecycle ---------------------------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        self.default_trigger("goal_point")
        self._algo = make_global_planner(self.config.planner_id, self.config.robot, self.config.ompl)
        self._lock = threading.Lock()  # one query at a time on the planner
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"{self.component_name}-plan")
        self._inflight: concurrent.futures.Future | None = None
        # The worker's state, under its own lock: a step that finds it busy leaves a request it
        # serves as soon as its query ends (checked and cleared with the busy flag, so none is lost).
        self._plan_state = threading.Lock()
        self._busy = False
        self._replan = False
        self._map_key: Any = None
        self._goal: np.ndarray | None = None
        self._goal_key: Any = None
        self._reached = False
        self.last_plan: np.ndarray | None = None
        self._followed: tuple[Any, np.ndarray, Any] | None = None  # (goal key, plan, its message) the re-plans may keep
        self._followed_progress = (math.inf, 0.0)  # (least plan left seen, node time it last shrank by KEPT_PLAN_PROGRESS)
        self.plans_kept = 0  # re-plans that kept the followed plan (shorter by too little, or none found)
        cm = self.config.costmap
        use_costmap = cm.enabled or bool(cm.keepout_mask or cm.speed_mask)
        self.costmap = LayeredCostmap(cm, self.config.robot.inner_radius) if use_costmap else None
        self._people_key: Any = None  # (people message, map key) of the layer the planner has
        if self.config.people.enabled:
            if not hasattr(self._algo, "set_extra_cost"):
                raise ValueError(f"{self.component_name}: PlannerConfig.people needs a grid planner (planner_id='CostToGo'), "
                                 f"got {self.config.planner_id!r}")
            if self.get_in_topic("people") is None:
                raise ValueError(f"{self.component_name}: PlannerConfig.people is enabled but the 'people' input has no topic "
                                 f"(wire the Behaviors' 'people' output to it)")
        self.create_path_services()

    def custom_on_deactivate(self) -> None:
        self._algo.cancel()

    def custom_on_shutdown(self) -> None:
        if hasattr(self, "_pool"):
            self._algo.cancel()
            self._pool.shutdown(wait=True, cancel_futures=True)

    # -- planning ------------------------------------------------------------------------------------------
    def _ensure_map(self) -> bool:
        msg = self.latest("map")
        if msg is None:
            self.fail_input("map", f"no map on {self.topic_name('map')} yet")
            return False
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.info.width, msg.info.height)
        if key != self._map_key:
            try:
                grid = grid_map_of(msg)
            except (BadInput, ValueError) as exc:
                self.fail_input("map", f"{self.topic_name('map')}: {exc}")
                return False
            if self.costmap is not None:
                master = self.costmap.set_map(grid)
                grid = self.costmap.planning_grid(grid)  # keepout zones are obstacles to the planner
                out = self.get_out_topic("global_costmap")
                if out is not None:
                    self.publish(out, grid_msg(master.to_occupancy(), grid.resolution, grid.origin, msg.header.frame_id or self.config.frames.world))
            self._algo.set_map(grid)
            self._map_key = key
        if self.config.people.enabled:
            self._apply_people()
        return True

    def _apply_people(self) -> None:
        """The people layer from the latest ``people`` band onto the planner's map (when either is
        new). A bad band is reported and the last good one kept: planning goes on."""
        msg = self.latest("people")
        if msg is None:
            return
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.info.width, msg.info.height, self._map_key)
        if key == self._people_key:
            return
        self._people_key = key
        try:
            walked = walked_points(grid_map_of(msg, what="people band"))
        except (BadInput, ValueError) as exc:
            self._report.warning("input:people", "[%s] %s: %s: keeping the last people layer", self.component_name,
                                 self.topic_name("people"), exc, logger=self.get_logger())
            return
        grid = self._algo.grid
        if grid is not None:
            self._algo.set_extra_cost(people_cost(grid, walked, self.config.people))

    def _plan_to_keep(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """What is left of the plan the robot follows towards ``goal``, when a re-plan may keep
        it (see ``replan_min_gain``): the robot on it and all of it free on the current map."""
        first_collision = getattr(self._algo, "first_collision", None)  # the sampling planners
        if self._followed is None or first_collision is None or self.config.replan_min_gain <= 0:
            return None
        goal_key, plan, _ = self._followed
        if goal_key != tuple(np.round(goal, 6)):
            return None
        ahead = path_ahead(plan, start[:2], KEPT_PLAN_MAX_OFFSET)
        if ahead is None or len(ahead) < 2 or first_collision(ahead) is not None:
            return None
        left, now = path_length(ahead), clock.now()
        least, since = self._followed_progress
        if left <= least - KEPT_PLAN_PROGRESS:
            self._followed_progress = (left, now)
        elif self.config.replan_stall_time > 0 and now - since > self.config.replan_stall_time:
            self.get_logger().info("[%s] no progress along the plan for %.0f s (%.2f m left): taking a new one",
                                   self.component_name, now - since, left)
            return None
        return ahead

    def _keep(self, why: str) -> tuple[bool, str, np.ndarray]:
        assert self._followed is not None
        _, plan, msg = self._followed
        self.plans_kept += 1
        # Published again as it was (its stamp too: a Controller following it goes on where it
        # is), so a late subscriber or a restarted Controller has it.
        self.publish(self.required_out_topic("plan"), msg)
        self.health_status.set_healthy()
        return True, f"kept the plan being followed ({why})", plan

    def plan_once(self, goal: np.ndarray, *, may_keep: bool = False) -> tuple[bool, str, np.ndarray]:
        """Plan from the current location to ``goal``; publishes the plan. (ok, message, path).
        ``may_keep``: a re-plan of the goal being driven to, which may keep the plan the robot
        follows (``PlannerConfig.replan_min_gain``); a kept plan is published again unchanged."""
        with self._lock:
            state = self.robot_state()
            if state is None or not self._ensure_map():
                return False, self.health_status.message, np.zeros((0, 3))
            start = state[0]
            for what, point in (("start", start), ("goal", goal)):
                zone = self.costmap.keepout_zone_at(point) if self.costmap is not None else None
                if zone is not None:
                    message = f"the {what} ({point[0]:.2f}, {point[1]:.2f}) is inside keepout zone {zone}"
                    self.fail_algorithm(self.config.planner_id, message)
                    return False, message, np.zeros((0, 3))
            kept = self._plan_to_keep(start, goal) if may_keep else None
            try:
                result = self._algo.plan(start, goal, timeout=self.config.planning_timeout)
            except ValueError as exc:  # a goal (or the robot) off the map
                self.fail_algorithm(self.config.planner_id, str(exc))
                return False, str(exc), np.zeros((0, 3))
            if not result.solved:
                why = f"{result.status}: {result.message}"
                if kept is not None:
                    self._report.warning("replan:kept", "[%s] a re-plan to (%.2f, %.2f) found no path (%s); following the last plan, "
                                         "still free", self.component_name, goal[0], goal[1], why, logger=self.get_logger())
                    return self._keep(f"a re-plan found none: {why}")
                self.fail_algorithm(self.config.planner_id, f"no path to ({goal[0]:.2f}, {goal[1]:.2f}): {why}")
                return False, why, np.zeros((0, 3))
            if self.config.smoother.enabled:
                master = self.costmap.master if self.costmap is not None else None
                result = attrs.evolve(result, path=smooth_path(result.path, self.config.smoother, master))
            if kept is not None and path_length(result.path) > (1.0 - self.config.replan_min_gain) * path_length(kept):
                return self._keep(f"the new one, {path_length(result.path):.2f} m, is not {self.config.replan_min_gain:.0%} "
                                  f"shorter than the {path_length(kept):.2f} m left")
            self.last_plan = result.path
            msg = path_msg(result.path, self.config.frames.world)
            self._followed = (tuple(np.round(goal, 6)), result.path, msg) if may_keep else None
            self._followed_progress = (path_length(result.path), clock.now())
            self.publish(self.required_out_topic("plan"), msg)
            self.health_status.set_healthy()
            return True, f"{result.length_m:.2f} m in {result.planning_time_s:.3f} s", result.path

    def block_tightest_spot(self) -> bool:
        """A recovery action (``Action(planner.block_tightest_spot)``, e.g. in a Controller's
        ``on_algorithm_fail`` ladder): the route the last plan takes looks open but the robot
        makes no progress along it, so put a temporary block at its tightest spot ahead of
        the robot and re-plan now. Grid planners only (``CostToGo``); blocks are forgotten when
        they leave no path. False (and the reason logged) when there is nothing to block."""
        block = getattr(self._algo, "block_tightest_spot", None)
        if block is None:
            self.get_logger().warning("[%s] block_tightest_spot: planner %s has no clearance grid (grid planners only)",
                                      self.component_name, self.config.planner_id)
            return False
        state = self.robot_state()
        if state is None:
            return False
        with self._lock:
            spot = block(state[0][:2])
        if spot is None:
            self.get_logger().warning("[%s] block_tightest_spot: no plan ahead of the robot to block", self.component_name)
            return False
        self.get_logger().info("[%s] blocked the plan's tightest spot at (%.2f, %.2f); re-planning", self.component_name, *spot)
        self._request_plan()
        return True

    def _distance_to_goal(self) -> float:
        state = self.robot_state()
        if state is None or self._goal is None:
            return math.inf
        return float(math.hypot(state[0][0] - self._goal[0], state[0][1] - self._goal[1]))

    def _check_reached(self, tolerance: float | None = None) -> bool:
        tolerance = self.config.distance_tolerance if tolerance is None else tolerance
        if self._goal is not None and not self._reached and self._distance_to_goal() <= tolerance:
            self._reached = True
            out = self.get_out_topic("reached_end")
            if out is not None:
                self.publish(out, Bool(data=True))
            self.health_status.set_healthy()
        return self._reached

    def _take_goal(self, msg: Any) -> None:
        if is_pixel_goal(msg):
            goal = self.pixel_goal(msg)
            if goal is None:
                return
        else:
            try:
                goal = goal_of(msg)
            except BadInput as exc:
                self.fail_input("goal_point", str(exc))
                return
        key = tuple(np.round(goal, 6))
        if key != self._goal_key:
            self._goal, self._goal_key, self._reached = goal, key, False
            out = self.get_out_topic("reached_end")
            if out is not None:
                self.publish(out, Bool(data=False))

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        goal_msg = msg if msg is not None else self.latest("goal_point")
        if goal_msg is not None:
            self._take_goal(goal_msg)
        if self._goal is None or self._check_reached():
            return
        self._request_plan()

    def _request_plan(self) -> None:
        """Plan towards the goal on the worker now or, while it runs a query, right after it."""
        goal = self._goal
        if goal is None:
            return
        with self._plan_state:
            if self._busy:
                self._replan = True
                return
            self._busy = True
        try:
            self._inflight = self._pool.submit(self._plan_in_worker, goal.copy())
        except BaseException:  # a pool shut down with the component: nothing runs
            with self._plan_state:
                self._busy = False
            raise

    def _plan_in_worker(self, goal: np.ndarray) -> None:
        # A step that found the worker busy (a new goal, or just its period) is served as soon as
        # this query ends: waiting for the next step would cost a whole period.
        try:
            while True:
                try:
                    self.plan_once(goal, may_keep=True)
                except Exception as exc:  # reported, never lost in the pool
                    self.get_logger().exception("[%s] planning failed: %s", self.component_name, exc)
                    self.health_status.set_fail_component(component_names=[self.component_name], message=f"{type(exc).__name__}: {exc}")
                if self._node is not None:
                    self.node.publish_status()
                with self._plan_state:
                    newest = self._goal
                    if newest is None or self._reached or not self._replan:
                        self._busy = False
                        return
                    self._replan = False
                goal = newest.copy()
        except BaseException:
            with self._plan_state:
                self._busy = False
            raise

    # -- Server and ActionServer ----------------------------------------------------------------------------
    @staticmethod
    def _request_goal(request: PlanPathRequest) -> np.ndarray:
        p = request.goal.pose
        goal = np.array([p.position.x, p.position.y] + ([] if request.any_heading else [p.orientation.yaw()]))
        if not np.all(np.isfinite(goal)):
            raise BadInput(f"goal: NaN/inf coordinates {goal.tolist()}")
        return goal

    def _main_srv_callback(self, request: PlanPathRequest) -> Any:
        async def serve() -> PlanPathResponse:
            try:
                goal = self._request_goal(request)
            except BadInput as exc:
                return PlanPathResponse(success=False, message=str(exc))
            loop = asyncio.get_running_loop()
            ok, message, path = await loop.run_in_executor(self._pool, self.plan_once, goal)
            self.node.publish_status()
            plan = path_msg(path, self.config.frames.world) if ok else Path(header=Header(stamp=clock.stamp(), frame_id=self.config.frames.world))
            return PlanPathResponse(success=ok, message=message, plan=plan)

        return serve()

    def _main_action_callback(self, goal_handle: Any) -> PlanPathResult:
        request: PlanPathGoal = goal_handle.goal
        goal = np.array([request.goal.position.x, request.goal.position.y])
        tolerance = float(request.end_tolerance.lateral_distance_error) or self.config.distance_tolerance
        if not np.all(np.isfinite(goal)) or not (math.isfinite(tolerance) and tolerance > 0):
            message = f"goal: NaN/inf coordinates {goal.tolist()}" if not np.all(np.isfinite(goal)) else \
                f"end_tolerance.lateral_distance_error must be a distance >= 0 (m), got {request.end_tolerance.lateral_distance_error!r}"
            self.get_logger().warning("[%s] %s: refused: %s", self.component_name, self.main_action_name, message)
            return PlanPathResult(success=False, message=message)
        self.get_logger().info("[%s] %s: goal (%.2f, %.2f), arrival within %.2f m", self.component_name,
                               self.main_action_name, goal[0], goal[1], tolerance)
        # A new goal preempts the running one (a second click in RViz): one loop re-plans, not two.
        self._action_goal = mine = getattr(self, "_action_goal", 0) + 1
        self._goal, self._goal_key, self._reached = goal, tuple(goal), False
        period = 1.0 / self.config.loop_rate
        last = PlanPathResult(success=False, message="cancelled")
        while not goal_handle.is_cancel_requested:
            if self._action_goal != mine:
                return PlanPathResult(success=False, message="preempted by a newer goal")
            if self._check_reached(tolerance):
                self.get_logger().info("[%s] %s: goal (%.2f, %.2f) reached", self.component_name, self.main_action_name, goal[0], goal[1])
                plan = path_msg(self.last_plan, self.config.frames.world) if self.last_plan is not None else Path()
                return PlanPathResult(success=True, message="goal reached", plan=plan)
            ok, message, path = self.plan_once(goal, may_keep=True)
            self.node.publish_status()
            length = path_length(path) if ok and len(path) > 1 else math.nan
            goal_handle.publish_feedback(PlanPathFeedback(distance_to_goal=self._distance_to_goal(), plan_length=length))
            if not ok and self.health_status.is_algorithm_fail:
                return PlanPathResult(success=False, message=message)
            deadline = clock.now() + period  # the node's clock: a replanning period in simulated seconds under a simulator
            while clock.now() < deadline and not goal_handle.is_cancel_requested and self._action_goal == mine:
                if self._check_reached(tolerance):
                    break
                time.sleep(min(0.05, period))
        self._goal = None
        return last
