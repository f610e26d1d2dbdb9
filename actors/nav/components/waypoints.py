"""``WaypointFollower``: Nav2's waypoint follower. Visits a list of poses one after the other
through the Planner's goal topic, runs a task at each (wait, a photo, any EMOS ``Action``),
loops (``number_of_loops``), reports progress, and can be cancelled and resumed.

    follower = WaypointFollower(component_name="waypoints", config=WaypointFollowerConfig(stop_on_failure=False))
    follower.inputs(reached_end=planner.get_out_topic(TopicsKeys.REACHED_END), planner_status=Topic(name="planner/status", ...))
    follower.outputs(goal_point=planner.get_in_topic(TopicsKeys.GOAL_POINT))
    follower.waypoint_task = WaitAtWaypoint(2.0)             # or tasks={index: task}

Action servers ``<name>/follow_waypoints`` (a task at each waypoint) and
``<name>/navigate_through_poses`` (the same list, no tasks), goal ``FollowWaypointsGoal``;
feedback: current waypoint, loop, straight-line distance left. Methods for events and recipes:
``start_mission(poses, number_of_loops)``, ``cancel_mission()`` (the robot stops: the Planner
gets its own position as goal), ``resume_mission()`` (from the waypoint it stopped at).

A waypoint fails when the Planner reports an ALGORITHM failure (no path) for
``planner_failure_time`` s, or when it is not reached within ``waypoint_timeout`` s (node
clock); ``stop_on_failure`` (Nav2's) then ends the mission or records the waypoint as missed
(index and reason, in the result's ``missed_waypoints``) and goes on.
"""
from __future__ import annotations

import concurrent.futures
import math
import threading
import time
from collections.abc import Mapping
from typing import Any, ClassVar

from attrs import define, field

from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs.geometry import Point, PointStamped, Pose
from emos.msgs.std import Header

from ..missions import TaskOutcome, WaypointMission, WaypointTask
from ..missions.mission import NAVIGATING, TASK
from ..missions.tasks import TaskContext
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, pose_of
from .mission_interfaces import FollowWaypointsFeedback, FollowWaypointsGoal, FollowWaypointsResult

__all__ = ["WaypointFollower", "WaypointFollowerConfig"]

ALGORITHM_FAILURE = 1  # ComponentStatus.status of an algorithm failure (the Planner's "no path")


@define(kw_only=True)
class WaypointFollowerConfig(NavComponentConfig):
    loop_rate: float = rate_field(5.0)
    stop_on_failure: bool = field(default=True)
    goal_tolerance: float = field(default=0.3, validator=in_range(min_value=1e-3, max_value=10.0))
    waypoint_timeout: float = field(default=300.0, validator=in_range(min_value=1.0, max_value=1e6))
    planner_failure_time: float = field(default=3.0, validator=in_range(min_value=0.0, max_value=600.0))
    goal_repeat_period: float = field(default=2.0, validator=in_range(min_value=0.1, max_value=600.0))


class WaypointFollower(NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry"), required=True),
        "reached_end": AllowedTopic(types=("Bool",), default=Topic(name="/reached_end", msg_type="Bool"), required=True),
        "planner_status": AllowedTopic(types=("ComponentStatus",), default=Topic(name="planner/status", msg_type="ComponentStatus")),
        "camera": AllowedTopic(types=("Image",), default=None),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "goal_point": AllowedTopic(types=("PointStamped",), default=Topic(name="/clicked_point", msg_type="PointStamped"), required=True),
    }
    config: WaypointFollowerConfig

    def __init__(self, component_name: str, config: WaypointFollowerConfig | None = None,
                 waypoint_task: WaypointTask | None = None, tasks: Mapping[int, WaypointTask] | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        self.waypoint_task = waypoint_task
        self.tasks = dict(tasks or {})
        for i, t in [(-1, waypoint_task), *self.tasks.items()]:
            if t is not None and not isinstance(t, WaypointTask):
                raise TypeError(f"WaypointFollower({component_name}): task {'for all' if i < 0 else f'of waypoint {i}'} must be a "
                                f"WaypointTask (WaitAtWaypoint, PhotoAtWaypoint, ActionAtWaypoint), got {type(t).__name__}")

    @classmethod
    def config_class(cls) -> type[WaypointFollowerConfig]:
        return WaypointFollowerConfig

    def custom_on_configure(self) -> None:
        self._lock = threading.Lock()
        self._mission: WaypointMission | None = None
        self._with_tasks = True
        self._last_goal: tuple[float, float, float] | None = None
        self._task: concurrent.futures.Future[TaskOutcome] | None = None
        self._task_cancel = threading.Event()
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"{self.component_name}-task")
        self.last_result: FollowWaypointsResult | None = None
        self._paused: WaypointMission | None = None
        self._misses_logged = 0  # of the current mission's misses (each is logged once)
        for name, with_tasks in (("follow_waypoints", True), ("navigate_through_poses", False)):
            self.create_action_server(f"{self.component_name}/{name}", FollowWaypointsGoal, FollowWaypointsFeedback,
                                      FollowWaypointsResult, lambda handle, t=with_tasks: self._serve(handle, t))

    def custom_on_shutdown(self) -> None:
        self._task_cancel.set()
        self._pool.shutdown(wait=False)

    def action_servers(self) -> dict[str, tuple[Any, Any, Any]]:
        types = (FollowWaypointsGoal, FollowWaypointsFeedback, FollowWaypointsResult)
        return {f"{self.component_name}/follow_waypoints": types, f"{self.component_name}/navigate_through_poses": types}

    # -- starting, cancelling, resuming -------------------------------------------------------------
    def start_mission(self, poses: list, number_of_loops: int = 0, start_index: int = 0, with_tasks: bool = True) -> bool:
        """Start visiting ``poses`` ((x, y[, yaw]) in the world frame)."""
        return self._start(poses, number_of_loops, start_index, with_tasks)[0]

    def _start(self, poses: list, number_of_loops: int, start_index: int, with_tasks: bool) -> tuple[bool, str]:
        try:
            mission = WaypointMission(poses, number_of_loops=int(number_of_loops), start_index=int(start_index),
                                      stop_on_failure=self.config.stop_on_failure)
        except (TypeError, ValueError) as exc:
            self.fail_algorithm("follow_waypoints", str(exc))
            return False, str(exc)
        self.last_result = None
        self._paused = None
        with self._lock:
            self._task_cancel.set()
            self._task_cancel = threading.Event()
            self._task = None
            self._mission, self._with_tasks = mission, with_tasks
            self._misses_logged = 0
            self._begin_leg(mission)
        self.get_logger().info("[%s] mission: %d waypoints, number_of_loops %d, from waypoint %d", self.component_name,
                               len(mission.waypoints), mission.number_of_loops, mission.index)
        return True, "started"

    def cancel_mission(self) -> bool:
        """Stop the mission where it is (the robot stops: the Planner's goal becomes its own
        position); ``resume_mission`` continues from the waypoint it was going to."""
        with self._lock:
            mission = self._mission
            if mission is None or mission.finished:
                return False
            self._task_cancel.set()
            self._result(mission, False, f"cancelled at waypoint {mission.index}")
            self._mission = None
            self._paused = mission
        pose = self._pose()
        if pose is not None:
            self._send_goal((pose[0], pose[1], pose[2]))
        return True

    def resume_mission(self) -> bool:
        paused = self._paused
        if paused is None:
            return False
        remaining_loops = paused.number_of_loops if paused.number_of_loops < 0 else paused.number_of_loops - paused.loop
        return self.start_mission(paused.waypoints, remaining_loops, paused.next_index, self._with_tasks)

    def mission_status(self) -> dict[str, Any]:
        """The mission now: active, state, waypoint, loop, and the last result (for a recipe's
        report, and for whoever resumed a mission it did not start by an action goal)."""
        with self._lock:
            m = self._mission
        r = self.last_result
        return {"active": m is not None and not m.finished, "paused": self._paused is not None,
                "state": None if m is None else m.state, "waypoint": None if m is None else m.index,
                "loop": None if m is None else m.loop,
                "result": None if r is None else {"success": r.success, "message": r.message, "loops_done": r.loops_done,
                                                   "missed_waypoints": list(r.missed_waypoints), "next_waypoint": r.next_waypoint}}

    # -- the loop ------------------------------------------------------------------------------------
    def _pose(self) -> Any:
        msg = self.latest("location")
        try:
            return None if msg is None else pose_of(msg)
        except BadInput:
            return None

    def _send_goal(self, wp: tuple[float, float, float]) -> None:
        self.publish(self.required_out_topic("goal_point"),
                     PointStamped(header=Header(frame_id=self.config.frames.world), point=Point(x=wp[0], y=wp[1])))
        self._goal_sent_at = clock.now()

    def _begin_leg(self, mission: WaypointMission) -> None:
        self._leg_started = clock.now()
        self._reached_msg = self.latest("reached_end")  # a later True is about this goal
        self._planner_failing_since: float | None = None
        self._last_goal = mission.current
        self._send_goal(mission.current)

    def _result(self, mission: WaypointMission, success: bool, message: str) -> None:
        self.last_result = FollowWaypointsResult(
            success=success, message=message, missed_waypoints=[f"{i}: {why}" for i, why in mission.missed],
            next_waypoint=mission.next_index, loops_done=mission.loop)

    def _execution_step(self, **kwargs: Any) -> None:
        with self._lock:
            mission = self._mission
            if mission is None or mission.finished:
                self.health_status.set_healthy()
                return
            if mission.state == NAVIGATING:
                self._navigate(mission)
            elif mission.state == TASK:
                self._run_task(mission)
            if mission.finished:
                self._result(mission, mission.success, mission.message)
                self.get_logger().info("[%s] mission ended: %s", self.component_name, mission.message)
            elif mission.state == NAVIGATING and self._last_goal != mission.current:
                self._begin_leg(mission)
        if mission.last_missed and not mission.finished:
            # The status says the miss until the next waypoint is reached; the log says it once.
            message = f"missed waypoint {mission.missed[-1][0]}: {mission.missed[-1][1]}"
            if len(mission.missed) != self._misses_logged:
                self._misses_logged = len(mission.missed)
                self.fail_algorithm("follow_waypoints", message)
            else:
                self.health_status.set_fail_algorithm(algorithm_names=["follow_waypoints"], message=message)
        elif mission.state == "failed":
            self.fail_algorithm("follow_waypoints", mission.message)
        else:
            self.health_status.set_healthy()

    def _navigate(self, mission: WaypointMission) -> None:
        now = clock.now()
        pose = self._pose()
        if pose is None:
            return
        left = math.dist(pose[:2], mission.current[:2])
        reached = self.latest("reached_end")
        if left <= self.config.goal_tolerance and reached is not None and reached is not self._reached_msg and reached.data:
            mission.on_reached()
            return
        status = self.latest("planner_status")
        if status is not None and int(status.status) == ALGORITHM_FAILURE:
            if self._planner_failing_since is None:
                self._planner_failing_since = now
            elif now - self._planner_failing_since >= self.config.planner_failure_time:
                mission.on_failure(f"unreachable: the planner says {status.message or 'it failed'}")
                return
        else:
            self._planner_failing_since = None
        if now - self._leg_started > self.config.waypoint_timeout:
            mission.on_failure(f"not reached within {self.config.waypoint_timeout:g} s ({left:.2f} m left)")
            return
        if now - self._goal_sent_at >= self.config.goal_repeat_period:
            self._send_goal(mission.current)  # a restarted Planner starts without a goal

    def _task_for(self, index: int) -> WaypointTask | None:
        return self.tasks.get(index, self.waypoint_task) if self._with_tasks else None

    def _run_task(self, mission: WaypointMission) -> None:
        if self._task is None:
            task = self._task_for(mission.index)
            if task is None:
                mission.on_task_done(True)
                return
            cancel = self._task_cancel
            ctx = TaskContext(index=mission.index, loop=mission.loop, waypoint=mission.current, latest=self._latest_by_name,
                              cancelled=cancel.is_set, run_ctx=self.node.ctx)
            self._task = self._pool.submit(_run_safely, task, ctx)
            return
        if not self._task.done():
            return
        outcome = self._task.result()
        self._task = None
        self.get_logger().info("[%s] task at waypoint %d: %s", self.component_name, mission.index, outcome.message)
        mission.on_task_done(outcome.ok, outcome.message)

    def _latest_by_name(self, name: str) -> Any:
        for key in ("camera",):
            t = self.get_in_topic(key)
            if t is not None and t.name == name:
                return self.latest(key)
        return self.get_input(name)

    # -- action server -------------------------------------------------------------------------------
    def _serve(self, handle: Any, with_tasks: bool) -> FollowWaypointsResult:
        goal: FollowWaypointsGoal = handle.goal
        poses = [_xyyaw(p) for p in goal.poses]
        ok, why = self._start(poses, goal.number_of_loops, goal.goal_index, with_tasks)
        if not ok:
            return FollowWaypointsResult(success=False, message=f"goal refused: {why}")
        mission = self._mission
        while True:
            with self._lock:
                current = self._mission
            if current is not mission or mission is None or mission.finished:
                break
            if handle.is_cancel_requested:
                self.cancel_mission()
                break
            pose = self._pose()
            handle.publish_feedback(FollowWaypointsFeedback(
                current_waypoint=mission.index, current_loop=mission.loop, state=mission.state,
                distance_remaining=mission.distance_remaining((pose[0], pose[1])) if pose is not None else -1.0))
            time.sleep(0.2)
        while self.last_result is None:
            time.sleep(0.05)
        return self.last_result


def _run_safely(task: WaypointTask, ctx: TaskContext) -> TaskOutcome:
    try:
        return task.run(ctx)
    except Exception as exc:  # noqa: BLE001 - a task's failure is the waypoint's, with the reason
        return TaskOutcome(False, f"{type(task).__name__} raised {type(exc).__name__}: {exc}")


def _xyyaw(p: Pose) -> tuple[float, float, float]:
    return (float(p.position.x), float(p.position.y), float(p.orientation.yaw()))
