"""Fallback ladders of simulated-time components wait for the simulated clock (real /clock rings)."""
import asyncio
import time

import pytest

from emos.core.clock import CLOCK_TOPIC
from emos.msgs import Clock, Time
from emos.supervisor.sim_pacing import SimPacer
from emos.transport.pubsub import Publisher

pytestmark = pytest.mark.unit


def _tick(pub, t):
    pub.publish(Clock(clock=Time.from_sec(t)))


def test_without_a_simulator_there_is_nothing_to_wait_for(ctx):
    pacer = SimPacer(ctx)
    assert pacer.now() is None
    # At once: the wait finishes on its first step, without suspending (no wall-clock budget).
    waiting = pacer.wait_until(pacer.now(), 1.0)
    with pytest.raises(StopIteration) as done:
        waiting.send(None)
    assert done.value.value is True


def test_a_step_waits_until_the_simulated_clock_has_advanced_by_its_period(ctx):
    pub = Publisher(ctx, CLOCK_TOPIC, Clock, publisher_id="sim")
    try:
        pacer = SimPacer(ctx, wall_cap=20.0)
        assert pacer.now() is None  # subscribed now: no tick since (the simulator ticks on)
        _tick(pub, 10.0)
        since = pacer.now()
        assert since == pytest.approx(10.0)

        async def scenario():
            waiting = asyncio.ensure_future(pacer.wait_until(since, 1.0, "[c] fallback ladder"))
            # The simulator runs slowly (a loaded machine): wall seconds pass, simulated ones do not.
            for t in (10.2, 10.5, 10.9):
                _tick(pub, t)
                await asyncio.sleep(0.15)
                assert not waiting.done(), t
            _tick(pub, 11.0)
            return await asyncio.wait_for(waiting, 5.0)

        assert asyncio.run(scenario()) is True
    finally:
        pub.close()


def test_a_stopped_clock_does_not_freeze_recovery_and_a_restarted_one_releases_at_once(ctx, caplog):
    pub = Publisher(ctx, CLOCK_TOPIC, Clock, publisher_id="sim")
    try:
        pacer = SimPacer(ctx, wall_cap=0.3)
        pacer.now()
        _tick(pub, 5.0)
        t0 = time.monotonic()
        assert asyncio.run(pacer.wait_until(5.0, 1.0, "[c] fallback ladder")) is False
        assert time.monotonic() - t0 >= 0.3  # it waited its wall_cap, then went on (returned False)
        assert "[c] fallback ladder: the simulated clock advanced 0.00 s in 0.3 s wall (waited for 1 s); going on" in caplog.text
        _tick(pub, 0.1)  # the simulator restarted: its time went back
        assert asyncio.run(pacer.wait_until(5.0, 1.0)) is True
    finally:
        pub.close()


def test_bad_pacing_settings_are_named():
    with pytest.raises(ValueError, match="wall_cap and poll must be > 0"):
        SimPacer(None, wall_cap=0.0)  # type: ignore[arg-type]
