"""Charging the stack's compute time in lockstep (``SimulatorConfig.compute_deadline``).

In lockstep the simulator waits for its consumers, so however long they compute, the robot sees
their command at once: the stack's computer would be infinitely fast. With a compute deadline
the consumers report the CPU time their steps took with each answer (``LockstepAck.compute``),
and a command that arrives with a tick acts only that much later in simulated time (the old
command keeps acting meanwhile), as on a robot whose computer takes that long. The charge of a
tick is the sum of its consumers' reports: the stack on one core, as the in-process benchmark
charges its navigator (:class:`~emos.actors.sim.barn_protocol.ControlDeadline`, shared here). A
tick charged more than the deadline (the control period) is a deadline miss.
"""
from __future__ import annotations

import logging
import math
from typing import Any

from emos.ratelimit import RateLimitedLog

from ..barn_protocol import ControlDeadline

log = logging.getLogger("emos.sim")
# A broken consumer answers every tick: its first bad report at once, then counted per 10 s.
_limited = RateLimitedLog(log, interval=10.0)


class ComputeCharge:
    def __init__(self, deadline_s: float, physics_dt: float) -> None:
        self.deadline = ControlDeadline(deadline_s, physics_dt)
        self._tick_s = 0.0
        self._held: list[tuple[int, Any]] = []  # (physics tick from which it acts, command), in arrival order
        self.bad_reports = 0

    def report(self, consumer: str, compute_s: Any) -> None:
        """One consumer's answer: CPU seconds of its steps since its previous answer."""
        if isinstance(compute_s, bool) or not isinstance(compute_s, (int, float)) or not math.isfinite(compute_s) \
                or not 0 <= compute_s < 3600:
            self.bad_reports += 1  # a broken or foreign answer charges nothing, and says so
            _limited.warning(f"report:{consumer}", "lockstep: %s reported a compute time of %r s (#%d such report); not charged",
                             consumer, compute_s, self.bad_reports)
            return
        self._tick_s += float(compute_s)

    def close_tick(self) -> int:
        """Every consumer answered: physics ticks the commands of this tick wait before acting."""
        delay = self.deadline.delay_ticks(self._tick_s)
        self._tick_s = 0.0
        return delay

    def hold(self, command: Any, acts_at_tick: int) -> None:
        self._held.append((acts_at_tick, command))

    def due(self, tick: int) -> Any | None:
        """The newest held command that acts by ``tick`` (older ones it supersedes are dropped)."""
        last = None
        for i, (at, _) in enumerate(self._held):
            if at <= tick:
                last = i
        if last is None:
            return None
        command = self._held[last][1]
        del self._held[: last + 1]
        return command

    def stats(self) -> dict:
        d = self.deadline
        return {"deadline_misses": d.misses, "charged_ticks": d.steps,
                "compute_mean_s": d.total_s / d.steps if d.steps else 0.0, "compute_worst_s": d.worst_s,
                "bad_reports": self.bad_reports}
