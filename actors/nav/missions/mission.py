"""``WaypointMission``: which waypoint is next, loops, and what a failure does (pure, no I/O).

Nav2's semantics: ``number_of_loops`` 0 visits the list once, N visits it N more times, -1
loops until cancelled; ``stop_on_failure`` True ends the mission at the first waypoint that
fails (unreachable, timed out, or its task failed), False records it as missed with the reason
and goes on to the next. ``next_index`` after a stop or a cancel is where a resumed mission
starts (the waypoint it was on: it was not reached).
"""
from __future__ import annotations

import math

__all__ = ["WaypointMission"]

NAVIGATING, TASK, DONE, FAILED = "navigating", "task", "done", "failed"


class WaypointMission:
    def __init__(self, waypoints: list[tuple[float, float, float]], *, number_of_loops: int = 0, start_index: int = 0,
                 stop_on_failure: bool = True) -> None:
        pts = [tuple(float(v) for v in w) for w in waypoints]
        if not pts:
            raise ValueError("WaypointMission: the waypoint list is empty")
        for i, w in enumerate(pts):
            if len(w) not in (2, 3) or not all(math.isfinite(v) for v in w):
                raise ValueError(f"WaypointMission: waypoint {i} must be a finite (x, y[, yaw]), got {waypoints[i]!r}")
        if not isinstance(number_of_loops, int) or number_of_loops < -1:
            raise ValueError(f"WaypointMission: number_of_loops must be -1 (forever), 0 (once) or more, got {number_of_loops!r}")
        if not 0 <= int(start_index) < len(pts):
            raise ValueError(f"WaypointMission: start_index {start_index} is not a waypoint (0..{len(pts) - 1})")
        self.waypoints = [(w[0], w[1], w[2] if len(w) == 3 else 0.0) for w in pts]
        self.number_of_loops = number_of_loops
        self.stop_on_failure = bool(stop_on_failure)
        self.index = int(start_index)
        self.loop = 0
        self.state = NAVIGATING
        self.missed: list[tuple[int, str]] = []
        self.reached: list[int] = []
        self.message = ""
        # The last waypoint's outcome: a miss stays the news until a waypoint is reached.
        self.last_missed = False

    @property
    def finished(self) -> bool:
        return self.state in (DONE, FAILED)

    @property
    def current(self) -> tuple[float, float, float]:
        return self.waypoints[self.index]

    @property
    def next_index(self) -> int:
        """Where a resumed mission starts."""
        return self.index

    def distance_remaining(self, position: tuple[float, float]) -> float:
        """Straight legs: to the current waypoint, then along the rest of this loop."""
        if self.finished:
            return 0.0
        d = math.dist(position, self.current[:2])
        for a, b in zip(self.waypoints[self.index:], self.waypoints[self.index + 1:]):
            d += math.dist(a[:2], b[:2])
        return d

    def on_reached(self) -> None:
        if self.state != NAVIGATING:
            raise RuntimeError(f"WaypointMission: reached in state {self.state}")
        self.reached.append(self.index)
        self.last_missed = False
        self.state = TASK

    def on_task_done(self, ok: bool, why: str = "") -> None:
        if self.state != TASK:
            raise RuntimeError(f"WaypointMission: task done in state {self.state}")
        if ok:
            self._advance()
        else:
            self.on_failure(f"task failed: {why}")

    def on_failure(self, why: str) -> None:
        """The current waypoint failed (unreachable, timed out, task failed)."""
        self.missed.append((self.index, why))
        self.last_missed = True
        if self.stop_on_failure:
            self.state = FAILED
            self.message = f"waypoint {self.index} {self.current[:2]} failed: {why}; stopped (stop_on_failure)"
            return
        self._advance()

    def _advance(self) -> None:
        self.index += 1
        if self.index >= len(self.waypoints):
            self.loop += 1
            if self.number_of_loops == -1 or self.loop <= self.number_of_loops:
                self.index = 0
            else:
                self.index = len(self.waypoints) - 1
                self.state = DONE
                self.message = (f"{self.loop} loop(s) done, {len(self.missed)} waypoint(s) missed" if self.missed
                                else f"{self.loop} loop(s) done")
                return
        self.state = NAVIGATING

    @property
    def success(self) -> bool:
        return self.state == DONE and not self.missed
