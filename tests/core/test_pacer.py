"""``emos.core.clock.Pacer``: an action loop steps once per period of the node's clock.

A loop that slept its period in wall time stepped several times per simulated period when the
simulator ran slower than real time (``emos run --lockstep`` on a busy machine), and the vision
follower, which takes each step to last one period, misjudged the person's speed. Here a
simulated clock moves at a fifth of real time: the paced loop must step once per
simulated period, however many wall periods that takes."""
from __future__ import annotations

import threading
import time

import pytest

from emos.core.clock import Pacer

pytestmark = pytest.mark.unit


class SlowClock:
    """Simulated seconds that advance by ``step`` whenever the test says so."""

    def __init__(self) -> None:
        self.t = 0.0
        self.lock = threading.Lock()

    def __call__(self) -> float:
        with self.lock:
            return self.t

    def advance(self, step: float) -> None:
        with self.lock:
            self.t += step


def test_a_paced_loop_steps_once_per_period_of_its_clock_not_of_the_wall():
    sim = SlowClock()
    pacer = Pacer(0.1, now=sim)
    steps: list[float] = []
    done = threading.Event()

    def loop() -> None:
        while not done.is_set():
            steps.append(sim())
            pacer.wait(done.is_set)

    worker = threading.Thread(target=loop)
    worker.start()
    for _ in range(250):  # 0.5 simulated seconds at a fifth of real time (2.5 s of wall time)
        time.sleep(0.01)
        sim.advance(0.002)
    done.set()
    worker.join(10)
    # At most one step at the start and one per 0.1 s of the clock after it: 6 over 0.5 s. A loop
    # paced on the wall clock would step about 25 times. (Fewer is allowed: a loop starved by a
    # busy machine skips the periods it missed.)
    assert 2 <= len(steps) <= 7, steps
    gaps = [b - a for a, b in zip(steps, steps[1:])]
    assert all(g >= 0.1 - 1e-9 for g in gaps), gaps


def _wait_in_thread(pacer: Pacer) -> threading.Event:
    returned = threading.Event()
    threading.Thread(target=lambda: (pacer.wait(), returned.set()), daemon=True).start()
    return returned


def test_missed_periods_are_skipped_and_time_that_goes_back_restarts_the_pacing():
    sim = SlowClock()
    pacer = Pacer(0.1, now=sim)
    first = _wait_in_thread(pacer)
    assert not first.wait(0.2)  # blocks until the clock has moved a period
    sim.advance(0.1)
    assert first.wait(10)
    stalled = _wait_in_thread(pacer)
    sim.advance(1.0)  # a stall of 10 periods ends this wait ...
    assert stalled.wait(10)
    after = _wait_in_thread(pacer)
    assert not after.wait(0.2)  # ... and the next waits a whole period: no backlog of 9 steps
    sim.advance(0.1)
    assert after.wait(10)
    with sim.lock:
        sim.t = 0.0  # the simulator restarted: the pacing starts again from there
    restarted = _wait_in_thread(pacer)
    assert not restarted.wait(0.2)
    sim.advance(0.1)
    assert restarted.wait(10)


def test_a_period_must_be_positive():
    with pytest.raises(ValueError, match="period must be > 0"):
        Pacer(0.0)
