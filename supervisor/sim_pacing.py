"""Fallback ladders of simulated-time components are paced on the simulated clock too.

``fallback_rate`` spaces a ladder's steps so that each one has had time to act before the next
is tried: a back-out must have been driven, a re-plan followed, before the robot is judged still
stuck. The supervisor runs the ladders on the wall clock, but a component with
``use_sim_time`` lives on the simulator's clock, and under lockstep a loaded machine slows that
clock down (several wall seconds per simulated second). Paced on the wall clock alone, a ladder
would fire its steps a fraction of a simulated second apart and spend its whole stuck recovery
(every back-out and block) while the first back-out is still being driven, then give up or
back into a wall.

So after each step of such a component's ladder the driver also waits until the simulated clock
has advanced by the step's period (on an idle machine the simulator runs faster than the wall
clock and this adds nothing). A clock that stops (the simulator paused or gone) must not freeze
recovery: after ``wall_cap`` wall seconds the ladder goes on regardless.
"""
from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from emos.transport.context import RunContext

log = logging.getLogger("emos.fallbacks")

POLL_S = 0.02  # wall: how often the simulated clock is looked at while a ladder waits for it
WALL_CAP_S = 30.0  # wall: the longest a ladder waits for a simulated clock that does not advance


class SimPacer:
    """Reads the run's simulated clock (the newest ``/clock``) and waits for it to advance."""

    def __init__(self, ctx: RunContext, wall_cap: float = WALL_CAP_S, poll: float = POLL_S) -> None:
        from emos.core.clock import run_clock

        if not (wall_cap > 0 and poll > 0):
            raise ValueError(f"SimPacer: wall_cap and poll must be > 0 s, got {wall_cap!r}, {poll!r}")
        self._clock = run_clock(ctx)
        self.wall_cap = wall_cap
        self.poll = poll

    def now(self) -> float | None:
        """Simulated seconds, or None when no simulator publishes ``/clock`` in this run."""
        return self._clock.time()

    async def wait_until(self, since: float | None, seconds: float, what: str = "") -> bool:
        """Return once the simulated clock is ``seconds`` past ``since`` (at once when ``since``
        is None: no simulated clock when the step was taken). False if ``wall_cap`` ran out first
        (logged, naming ``what``), or the clock went back (the simulator restarted: True)."""
        if since is None:
            return True
        deadline = time.monotonic() + self.wall_cap
        while True:
            t = self.now()
            if t is not None and (t - since >= seconds or t < since):
                return True
            if time.monotonic() >= deadline:
                log.warning("%s: the simulated clock advanced %s in %g s wall (waited for %g s); going on",
                            what or "fallbacks", "nothing" if t is None else f"{t - since:.2f} s", self.wall_cap, seconds)
                return False
            await asyncio.sleep(self.poll)


__all__ = ["POLL_S", "SimPacer", "WALL_CAP_S"]
