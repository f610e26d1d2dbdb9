"""Global planning in SE2 over an occupancy grid: OMPL for search, python-fcl for collisions.

Why the planner can promise a collision-free path: OMPL checks motions at discrete states.
The states it checks are at most ``L`` apart in x-y and ``2L`` in yaw (its SE2 metric weighs yaw
by 0.5), so any body point moves at most ``L * (1 + 2R)`` between two checks (R = the robot's
outer radius). Requiring a clearance above half of that, ``margin``, at every checked state
makes the continuous motion collision-free. The final path is then densified and verified with
plain fcl collision queries before it is returned; a path that fails is never returned.
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from emos.actors.nav.collision import MapCollisionChecker
from emos.actors.nav.maps.grid import OccupancyGridMap

from .config import OMPLConfig
from .interpolation import interpolate_se2, path_length, wrap_angle
from .registry import make_planner
from .result import PlanResult

__all__ = ["OMPLGeometricPlanner", "ANY_HEADING_SAMPLES"]

#: Headings offered to OMPL when a goal is given without yaw (x, y only).
ANY_HEADING_SAMPLES = 16


def _ompl() -> tuple[Any, Any, Any]:
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("global planning needs the OMPL bindings: pip install 'emos[nav]'") from exc
    return ob, og, ou


def _pose(name: str, value: Sequence[float], allow_xy: bool) -> tuple[float, float, float | None]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 2 and allow_xy:
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}: expected finite (x, y), got {arr.tolist()}")
        return float(arr[0]), float(arr[1]), None
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        want = "(x, y) or (x, y, yaw)" if allow_xy else "(x, y, yaw)"
        raise ValueError(f"{name}: expected finite {want}, got {np.asarray(value).tolist()}")
    return float(arr[0]), float(arr[1]), float(wrap_angle(arr[2]))


class OMPLGeometricPlanner:
    """Plans collision-free SE2 paths for a robot on an occupancy grid.

    Build it with an :class:`OMPLConfig` and the robot (a ``RobotConfig``, or its
    ``geometry_type`` / ``geometry_params``), give it a map with :meth:`set_map`, then call
    :meth:`plan`. One query at a time per instance; :meth:`cancel` may be called from any
    thread to stop the query in progress.
    """

    def __init__(
        self,
        config: OMPLConfig | None = None,
        robot: Any = None,
        *,
        geometry_type: Any = None,
        geometry_params: Any = None,
    ) -> None:
        self.config = config if config is not None else OMPLConfig()
        if not isinstance(self.config, OMPLConfig):
            raise TypeError(f"OMPLGeometricPlanner: config must be an OMPLConfig, got {type(self.config).__name__}")
        if robot is not None:
            geometry_type, geometry_params = robot.geometry_type, robot.geometry_params
        if geometry_type is None or geometry_params is None:
            raise ValueError("OMPLGeometricPlanner: give a RobotConfig or geometry_type and geometry_params")
        self.geometry_type = geometry_type
        self.geometry_params = geometry_params
        self.checker: MapCollisionChecker | None = None
        self._si: Any = None
        self._margin_slot = [0.0]
        self._base_margin = 0.0
        self._ptc_lock = threading.Lock()
        self._ptc: Any = None
        self._cancelled = False
        ob, og, ou = _ompl()
        ou.setLogLevel(getattr(ou, f"LOG_{self.config.log_level.upper()}"))

    # ---- map --------------------------------------------------------------------------
    def set_map(self, grid: OccupancyGridMap) -> None:
        """Use ``grid`` for all following queries (builds the fcl scene and the SE2 space)."""
        ob, _, _ = _ompl()
        cfg = self.config
        checker = MapCollisionChecker(
            grid,
            self.geometry_type,
            self.geometry_params,
            occupied_threshold=cfg.occupied_threshold,
            unknown_is_occupied=cfg.unknown_is_occupied,
        )
        xmin, ymin, xmax, ymax = grid.world_bounds()
        space = ob.SE2StateSpace()
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0, xmin)
        bounds.setLow(1, ymin)
        bounds.setHigh(0, xmax)
        bounds.setHigh(1, ymax)
        space.setBounds(bounds)
        si = ob.SpaceInformation(space)
        radius = checker.outer_radius
        # Check spacing L: body points move <= L (1 + 2R) between checks; margin is half that.
        step = grid.resolution / (2.0 * (1.0 + 2.0 * radius))
        self._base_margin = 0.5 * step * (1.0 + 2.0 * radius)
        si.setStateValidityChecker(self._make_validity_callback(checker))
        si.setStateValidityCheckingResolution(step / space.getMaximumExtent())
        si.setup()
        self.checker = checker
        self._si = si
        self._space = space

    def _make_validity_callback(self, checker: MapCollisionChecker) -> Any:
        # A closure over locals: OMPL calls this hundreds of thousands of times per second.
        dist = checker.distance_map
        grid = checker.grid
        res = grid.resolution
        width, height = grid.width, grid.height
        ox, oy, oyaw = grid.origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        free_above = checker.outer_radius + res * math.sqrt(2.0)
        blocked_below = checker.inner_radius - res * math.sqrt(2.0) / 2.0
        floor = math.floor
        # The margin changes per query; share it through a one-slot list rather than `self`,
        # so the callback held by OMPL (C++) does not keep the planner alive in a cycle.
        margin_slot = self._margin_slot

        def is_valid(state: Any) -> bool:
            x = state.getX()
            y = state.getY()
            dx, dy = x - ox, y - oy
            ix = floor((c * dx + s * dy) / res)
            iy = floor((-s * dx + c * dy) / res)
            if ix < 0 or iy < 0 or ix >= width or iy >= height:
                return False
            d = dist[iy, ix]
            margin = margin_slot[0]
            if d > free_above + margin:
                return True
            if d < blocked_below:
                return False
            return checker.min_distance(x, y, state.getYaw()) > margin

        return is_valid

    # ---- planning ---------------------------------------------------------------------
    def plan(
        self,
        start: Sequence[float],
        goal: Sequence[float],
        *,
        timeout: float | None = None,
    ) -> PlanResult:
        """Plan from ``start`` (x, y, yaw) to ``goal`` (x, y, yaw), or to (x, y) at any heading.

        Returns a :class:`PlanResult`; an unreachable or blocked goal gives ``solved=False``
        after at most ``timeout`` (default ``config.planning_timeout``) seconds. Poses outside
        the map raise ``ValueError``.
        """
        if self.checker is None or self._si is None:
            raise RuntimeError("OMPLGeometricPlanner.plan: call set_map(grid) first")
        ob, og, _ = _ompl()
        cfg = self.config
        budget = cfg.planning_timeout if timeout is None else float(timeout)
        if not (math.isfinite(budget) and budget > 0):
            raise ValueError(f"plan: timeout must be > 0 s, got {timeout!r}")
        sx, sy, syaw = _pose("start", start, allow_xy=False)
        assert syaw is not None  # allow_xy=False: a start always has its yaw
        gx, gy, gyaw = _pose("goal", goal, allow_xy=True)
        grid = self.checker.grid
        for name, (x, y) in (("start", (sx, sy)), ("goal", (gx, gy))):
            if not grid.in_bounds(grid.world_to_grid(np.array([x, y]))):
                xmin, ymin, xmax, ymax = grid.world_bounds()
                raise ValueError(
                    f"plan: {name} ({x:.3f}, {y:.3f}) is outside the map "
                    f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}]"
                )
        name = cfg.planner_name
        checker = self.checker

        def failed(status: str, message: str, t_plan: float = 0.0) -> PlanResult:
            return PlanResult(False, np.zeros((0, 3)), name, status, t_plan, 0.0, 0.0, message)

        if not checker.is_valid_exact(sx, sy, syaw):
            return failed("INVALID_START", "the robot collides with the map at the start pose")
        if gyaw is not None:
            goal_yaws = [gyaw]
        else:
            # Any heading will do; offer the ones closest to the direction of travel first so
            # the straight-line case arrives facing forward.
            travel = math.atan2(gy - sy, gx - sx)
            candidates = wrap_angle(travel + np.arange(ANY_HEADING_SAMPLES) * 2.0 * math.pi / ANY_HEADING_SAMPLES)
            goal_yaws = list(candidates[np.argsort(np.abs(wrap_angle(candidates - travel)), kind="stable")])
        goal_yaws = [float(a) for a in goal_yaws if checker.is_valid_exact(gx, gy, float(a))]
        if not goal_yaws:
            return failed("INVALID_GOAL", "the robot collides with the map at the goal")
        # A robot parked closer to a wall than the margin must still be able to leave.
        clearances = [checker.min_distance(sx, sy, syaw)] + [checker.min_distance(gx, gy, a) for a in goal_yaws]
        self._margin_slot[0] = min(self._base_margin, 0.5 * min(clearances))

        si = self._si
        pdef = ob.ProblemDefinition(si)
        start_state = si.allocState()
        start_state.setX(sx)
        start_state.setY(sy)
        start_state.setYaw(syaw)
        pdef.addStartState(start_state)
        goal_states = ob.GoalStates(si)
        for yaw in goal_yaws:
            g = si.allocState()
            g.setX(gx)
            g.setY(gy)
            g.setYaw(yaw)
            goal_states.addState(g)
        goal_states.setThreshold(cfg.goal_tolerance)
        pdef.setGoal(goal_states)
        objective = ob.PathLengthOptimizationObjective(si)
        if cfg.first_solution:
            # Every path satisfies an infinite cost threshold, so an optimizing planner (RRT*,
            # PRM, BIT*...) stops at its first solution instead of refining it until the timeout.
            objective.setCostThreshold(ob.Cost(math.inf))
        pdef.setOptimizationObjective(objective)

        # A goal in plain sight: the straight SE2 motion is the shortest path, so no search is
        # needed (and OMPL 2.0's AORRTC reports such queries as a zero-length failure).
        t0 = time.perf_counter()
        for k in range(goal_states.getStateCount()):
            if si.checkMotion(start_state, goal_states.getState(k)):
                g = goal_states.getState(k)
                states = np.array([(sx, sy, syaw), (g.getX(), g.getY(), g.getYaw())])
                return self._finish(states, name, time.perf_counter() - t0, 0.0, "straight line")

        planner = make_planner(cfg.planner_id, si, cfg.planner_params)
        planner.setProblemDefinition(pdef)
        planner.setup()
        # A C++-side timed condition: cancel() can end it from another thread without any
        # Python call per planner iteration.
        ptc = ob.timedPlannerTerminationCondition(budget)
        if cfg.first_solution:
            # Planners that ignore the cost threshold (AORRTC) stop when the problem holds an
            # exact solution.
            ptc = ob.plannerOrTerminationCondition(ptc, ob.exactSolnPlannerTerminationCondition(pdef))
        with self._ptc_lock:
            self._ptc, self._cancelled = ptc, False
        try:
            t0 = time.perf_counter()
            status = planner.solve(ptc)
            t_plan = time.perf_counter() - t0
        finally:
            with self._ptc_lock:
                self._ptc = None
                cancelled = self._cancelled
        status_name = status.getStatus().name
        if status_name != "EXACT_SOLUTION" or not pdef.hasExactSolution():
            if cancelled:
                return failed("CANCELLED", "cancelled before a solution was found", t_plan)
            if status_name == "APPROXIMATE_SOLUTION":
                status_name = "TIMEOUT"
            return failed(status_name, f"no exact solution within {budget:.3g} s", t_plan)

        raw = pdef.getSolutionPath()
        t_simpl = 0.0
        if cfg.simplify and cfg.simplification_timeout > 0:
            simplifier = og.PathSimplifier(si, goal_states, objective)
            t1 = time.perf_counter()
            simplifier.simplify(raw, cfg.simplification_timeout)
            t_simpl = time.perf_counter() - t1
        states = np.array([(st.getX(), st.getY(), st.getYaw()) for st in raw.getStates()], dtype=np.float64)
        return self._finish(states, name, t_plan, t_simpl)

    def cancel(self) -> bool:
        """Stop the query in progress (from any thread). An anytime planner that already has a
        solution returns it; otherwise the result is ``solved=False``, status ``CANCELLED``.
        Returns False if no query was running."""
        with self._ptc_lock:
            if self._ptc is None:
                return False
            self._cancelled = True
            self._ptc.terminate()
            return True

    def first_collision(self, path: np.ndarray) -> np.ndarray | None:
        """The first pose along ``path`` ((N, 3) poses, consecutive poses joined by the
        straight SE2 motion) at which the robot would touch the current map, or None when the
        whole path is free (with the fcl check of a plan's final verification)."""
        checker = self.checker
        if checker is None:
            raise RuntimeError("OMPLGeometricPlanner.first_collision: call set_map first")
        res = checker.grid.resolution
        radius = max(checker.outer_radius, 1e-6)
        # Dense enough that no body point moves more than res/4 between checked poses.
        dense = interpolate_se2(np.asarray(path, dtype=np.float64).reshape(-1, 3), res / 8.0, res / (8.0 * radius))
        ok = checker.are_valid(dense, exact=True)
        return None if ok.all() else dense[~ok][0]

    def _finish(
        self, states: np.ndarray, name: str, t_plan: float, t_simpl: float, message: str = ""
    ) -> PlanResult:
        bad = self.first_collision(states)
        if bad is not None:
            return PlanResult(
                False, np.zeros((0, 3)), name, "PATH_IN_COLLISION", t_plan, t_simpl, 0.0,
                f"final fcl verification rejected the path at ({bad[0]:.3f}, {bad[1]:.3f}, {bad[2]:.3f})",
            )
        path = interpolate_se2(states, self.config.path_resolution)
        return PlanResult(True, path, name, "EXACT_SOLUTION", t_plan, t_simpl, path_length(path), message)
