"""``DockingServer``: Nav2's docking server. ``dock_robot`` finds the charging dock in the scan
and drives onto it; ``undock_robot`` backs off it to the staging distance, checking behind.

    docking = DockingServer(component_name="docking", config=DockingServerConfig(docks={"home": (0.35, 6.0, 0.0)}))
    Event(low_battery, Action(method=docking.dock_robot))      # or the dock_robot action server

The dock database (``docks``: id -> (x, y, yaw) of the dock's apex in the world frame, its
opening along yaw) gives the estimate the scan search starts from, as Nav2's dock plugins take
one; the robot must be near the staging pose (``staging_offset`` m out on the dock's axis),
where a navigation goal brings it (Nav2: ``navigate_to_staging_pose``). The final approach runs
on the dock pose detected in each scan (:mod:`emos.actors.nav.docking`), in the robot frame, so
localization error does not move the contacts. A dock not found within ``search_timeout``
(node clock s) fails the goal with the reason and the robot is stopped; so does a dock lost
during the approach for that long. Commands go to ``robot_command``: in the shipped stacks the
DriveManager's ``/control/docking`` input, above the recovery behaviors and the Controller
(``stacks.DOCKING_COMMAND``). The action-server plumbing is :mod:`.motion_actions`'.
"""
from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np
from attrs import define, field

from emos.config.validators import in_range
from emos.core import clock

from .. import recovery as R
from ..controllers.sensors import obstacle_points
from ..docking import DockApproach, DockSpec, compose, detect_dock, invert
from .base import NavComponentConfig, rate_field
from .convert import BadInput, scan_of
from .mission_interfaces import DockRobotFeedback, DockRobotGoal, DockRobotResult, UndockRobotGoal
from .motion_actions import MotionActionServer

__all__ = ["DockingServer", "DockingServerConfig"]


def _docks(value: Any) -> dict[str, tuple[float, float, float]]:
    if not isinstance(value, Mapping):
        raise TypeError(f"DockingServerConfig.docks: expected a dict of dock id -> (x, y, yaw), got {type(value).__name__}")
    out = {}
    for k, v in value.items():
        pose = tuple(float(x) for x in v)
        if not isinstance(k, str) or not k or len(pose) != 3 or not all(math.isfinite(x) for x in pose):
            raise ValueError(f"DockingServerConfig.docks[{k!r}]: expected a non-empty id and a finite (x, y, yaw), got {v!r}")
        out[k] = pose
    return out


@define(kw_only=True)
class DockingServerConfig(NavComponentConfig):
    """Nav2's names where they apply: ``staging_x_offset`` is ``staging_offset`` here (m out of
    the dock on its axis), ``docked_offset`` (m from the apex to the docked robot's centre)."""

    loop_rate: float = rate_field(10.0)
    docks: dict[str, tuple[float, float, float]] = field(factory=dict, converter=_docks)
    search_timeout: float = field(default=5.0, validator=in_range(min_value=0.1, max_value=600.0))
    max_speed: float = field(default=0.15, validator=in_range(min_value=0.01, max_value=2.0))
    docked_offset: float = field(default=0.35, validator=in_range(min_value=0.05, max_value=5.0))
    staging_offset: float = field(default=0.6, validator=in_range(min_value=0.1, max_value=5.0))
    safety_margin: float = field(default=0.03, validator=in_range(min_value=0.0, max_value=1.0))
    dock_approach_timeout: float = field(default=60.0, validator=in_range(min_value=1.0, max_value=3600.0))

    def spec(self) -> DockSpec:
        return DockSpec(docked_offset=self.docked_offset, staging_offset=self.staging_offset)


class DockingServer(MotionActionServer):
    ACTIONS = (("dock_robot", DockRobotGoal, DockRobotFeedback, DockRobotResult, "_serve_dock"),
               ("undock_robot", UndockRobotGoal, DockRobotFeedback, DockRobotResult, "_serve_undock"))
    config: DockingServerConfig

    @classmethod
    def config_class(cls) -> type[DockingServerConfig]:
        return DockingServerConfig

    def custom_on_configure(self) -> None:
        import scipy.optimize  # noqa: F401 - the fit's import takes a while: here, not in a step (the heartbeat)

        self._lock = threading.Lock()
        self._job: dict[str, Any] | None = None
        self.is_docked = False
        self.last_result: DockRobotResult | None = None
        self._create_action_servers()

    # -- actions -------------------------------------------------------------------------------------
    def dock_robot(self, dock_id: str = "") -> bool:
        """Start docking on ``dock_id`` (the first dock when empty); False (and why, in the
        status) when it cannot start."""
        return self._start_dock(dock_id)[0]

    def undock_robot(self) -> bool:
        return self._start_undock()[0]

    def _start_dock(self, dock_id: str) -> tuple[bool, str]:
        if not self.config.docks:
            return self._fail_now("dock_robot", "dock_robot refused: the dock database (docks) is empty")
        dock_id = dock_id or next(iter(self.config.docks))
        if dock_id not in self.config.docks:
            return self._fail_now("dock_robot", f"dock_robot refused: no dock {dock_id!r}; docks are {', '.join(self.config.docks)}")
        pose = self._pose()
        if pose is None:
            return self._fail_now("dock_robot", f"dock_robot refused: no pose on {self.topic_name('location')}")
        estimate = compose(invert(pose), self.config.docks[dock_id])  # the dock in the robot frame
        job = {"kind": "dock", "dock_id": dock_id, "state": "INITIAL_PERCEPTION", "started": clock.now(), "seen": clock.now(),
               "estimate": estimate, "pose": pose, "approach": DockApproach(self.config.spec(), max_speed=self.config.max_speed),
               "reason": "", "result": None, "left": math.inf}
        with self._lock:
            self._job = job
        self.is_docked = False
        return True, f"docking on {dock_id!r}"

    def _start_undock(self) -> tuple[bool, str]:
        pose = self._pose()
        if pose is None:
            return self._fail_now("undock_robot", f"undock_robot refused: no pose on {self.topic_name('location')}")
        job = {"kind": "undock", "state": "UNDOCKING", "started": clock.now(), "pose": pose, "result": None,
               "left": self.config.staging_offset}
        with self._lock:
            self._job = job
        return True, "undocking"

    def _fail_now(self, what: str, reason: str) -> tuple[bool, str]:
        self.fail_algorithm(what, reason)
        self.last_result = DockRobotResult(success=False, message=reason)
        return False, reason

    # -- the loop ------------------------------------------------------------------------------------
    def _end(self, job: dict[str, Any], success: bool, message: str, err: tuple[float, float] = (0.0, 0.0)) -> None:
        self._stop_robot()  # the robot stops either way
        job["result"] = DockRobotResult(success=success, message=message, error_m=err[0], error_deg=err[1])
        self.last_result = job["result"]
        if success:
            self.health_status.set_healthy()
            self.get_logger().info("[%s] %s", self.component_name, message)
        else:
            self.fail_algorithm("dock_robot" if job["kind"] == "dock" else "undock_robot", message)

    def _execution_step(self, **kwargs: Any) -> None:
        with self._lock:
            job = self._job
        if job is None or job["result"] is not None:
            if job is not None and job.get("cancel") and not job.get("stopped"):
                self._stop_robot()
                job["stopped"] = True
            return
        if job.get("cancel"):
            self._end(job, False, f"{job['kind']} cancelled")
            return
        pose = self._pose()
        scan_msg = self.latest("sensor_data")
        if pose is None or scan_msg is None:
            self._end(job, False, f"{job['kind']} stopped: no {'pose' if pose is None else 'scan'}")
            return
        try:
            scan = scan_of(scan_msg)
        except BadInput as exc:
            self._end(job, False, f"{job['kind']} stopped: {exc}")
            return
        points = obstacle_points(scan)
        if job["kind"] == "undock":
            self._undock_step(job, pose, points, scan)
        else:
            self._dock_step(job, pose, points)

    def _dock_step(self, job: dict[str, Any], pose: np.ndarray, points: np.ndarray) -> None:
        now = clock.now()
        # Carry the last estimate by the odometry's motion since then (robot frame -> robot frame).
        moved = compose(invert(pose), job["pose"])
        estimate = compose(moved, job["estimate"])
        job["pose"] = pose
        tracking = job["state"] == "CONTROLLING"  # a dock seen a step ago needs one fit, not three
        det = detect_dock(points, estimate, self.config.spec(), yaw_starts=(0.0,) if tracking else (0.0, 0.35, -0.35))
        if not det.found:
            job["estimate"] = estimate
            job["reason"] = det.reason
            self._stop_robot()
            if now - job["seen"] > self.config.search_timeout:
                where = "found" if job["state"] == "INITIAL_PERCEPTION" else "seen again"
                self._end(job, False, f"dock {job['dock_id']!r} not {where} in the scan within {self.config.search_timeout:g} s "
                                      f"({det.reason}): robot stopped")
            return
        job["estimate"], job["seen"], job["state"] = det.pose, now, "CONTROLLING"
        if now - job["started"] > self.config.dock_approach_timeout:
            self._end(job, False, f"dock {job['dock_id']!r}: not docked within dock_approach_timeout "
                                  f"{self.config.dock_approach_timeout:g} s (something holds the robot back): robot stopped")
            return
        approach: DockApproach = job["approach"]
        along, lateral, heading = approach.errors(det.pose)
        job["left"] = max(along, 0.0)
        v, w, done = approach.step(det.pose)
        if done:
            self.is_docked = True
            self._end(job, True, f"docked on {job['dock_id']!r} ({abs(along) * 100:.1f} cm along, {abs(lateral) * 100:.1f} cm "
                                 f"across, {math.degrees(abs(heading)):.1f} deg)",
                      (math.hypot(along, lateral), math.degrees(abs(heading))))
            return
        self._drive(np.array([v, 0.0, w]))

    def _undock_step(self, job: dict[str, Any], pose: np.ndarray, points: np.ndarray, scan: Any) -> None:
        done = math.dist(pose[:2], job["pose"][:2])
        left = self.config.staging_offset - done
        job["left"] = max(left, 0.0)
        if left <= 0.01:
            self.is_docked = False
            self._end(job, True, f"undocked: {done:.2f} m off the dock")
            return
        rear = R.scan_covers_rear(scan)
        plan = R.plan_back_up(self.config.robot, points, left, speed=min(self.config.max_speed, 0.1),
                              dt=1.0 / self.config.loop_rate, margin=self.config.safety_margin, rear_seen=rear)
        if not plan.feasible:
            self._end(job, False, f"undock stopped after {done:.2f} m: {plan.reason}")
            return
        self._drive(plan.commands[0])

    # -- action servers ------------------------------------------------------------------------------
    def _wait(self, handle: Any) -> DockRobotResult:
        with self._lock:
            job = self._job
        assert job is not None
        result: DockRobotResult = self._follow_goal(
            handle, lambda: job["result"], cancel=lambda: job.__setitem__("cancel", True),
            feedback=lambda: DockRobotFeedback(state=job["state"], distance_left=float(min(job["left"], 1e6))))
        return result

    def _serve_dock(self, handle: Any) -> DockRobotResult:
        ok, why = self._start_dock(handle.goal.dock_id)
        return self._wait(handle) if ok else DockRobotResult(success=False, message=why)

    def _serve_undock(self, handle: Any) -> DockRobotResult:
        ok, why = self._start_undock()
        return self._wait(handle) if ok else DockRobotResult(success=False, message=why)
