"""``emos.core.clock.Pacer``: an action loop steps once per period of the node's clock; and a
step worker held by a ``SimTimeDriver`` finishes a tick's steps before the tick is answered.

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


# -- in a node on simulated time: the loop steps inside the ticks ---------------------------------------
@pytest.fixture
def driver():
    """A real ``SimTimeDriver`` (the one a ``use_sim_time`` node owns) on a private run's rings."""
    from emos.core import clock
    from emos.core.clock import SimTimeDriver
    from emos.transport.context import RunContext
    from emos.transport.waker import Waker

    ctx = RunContext.create()
    waker = Waker(ctx)
    d = SimTimeDriver(ctx, "follower", waker, period=lambda: 0.05)
    d.ctx = ctx  # for the test's own subscribers
    yield d
    clock.release_driven_time()  # handle() drove this process's clock: give it back to the next test
    d.close()
    waker.close()
    ctx.remove_everything()


def _tick(t: float):
    from emos.msgs import Clock
    from emos.msgs.std import Time

    return Clock(clock=Time.from_sec(t))


def test_a_loop_on_a_sim_time_node_steps_inside_the_tick_that_makes_its_period_due(driver):
    """The node answers a tick only after the loop's step: each ``handle`` returns with the step
    it released already taken, one per 0.1 s of ticks, whatever the wall clock does."""
    pacer = Pacer(0.1, driver=driver)
    steps: list[float] = []
    done = threading.Event()

    def loop() -> None:
        with pacer:
            while not done.is_set():
                steps.append(driver.time if driver.time is not None else -1.0)
                time.sleep(0.02)  # a step that takes a while: the tick must wait for it
                pacer.wait(done.is_set)

    worker = threading.Thread(target=loop)
    worker.start()
    while not driver._loops:  # the first step runs at once; the loop joins at its first wait
        time.sleep(0.001)
    seen = []
    for i in range(1, 101):  # 1.0 simulated second in ticks of 0.01 s, as fast as the test can
        driver.handle(_tick(0.01 * i), None)
        seen.append(len(steps))
    done.set()
    worker.join(10)
    assert not worker.is_alive()
    # Joined at t = None (no tick yet): armed by the first tick (0.01), due every 0.1 s after it.
    # The step a tick releases is in `steps` when `handle` returns, stamped with that tick's time.
    assert steps[1:] == pytest.approx([0.11, 0.21, 0.31, 0.41, 0.51, 0.61, 0.71, 0.81, 0.91]), steps
    assert seen[10] == 2 and seen[9] == 1  # tick 0.11 (index 10) released and waited for the second step
    assert not driver._loops  # closed with the loop: no tick waits for it any more


def test_the_loops_cpu_is_charged_to_the_tick_it_stepped_in(driver):
    """A lockstep simulator charges the stack's compute from the answers: the loop's step is
    the node's work like a Timed step, so its thread CPU is in the answer of its tick."""
    from emos.core.clock import ack_topic
    from emos.msgs import LockstepAck
    from emos.transport.pubsub import Subscriber

    acks = Subscriber(driver.ctx, ack_topic("follower"), LockstepAck, queue_size=64)
    pacer = Pacer(0.1, driver=driver)
    done = threading.Event()

    def loop() -> None:
        with pacer:
            while not done.is_set():
                end = time.thread_time() + 0.03
                while time.thread_time() < end:  # 30 ms of this thread's CPU
                    pass
                pacer.wait(done.is_set)

    worker = threading.Thread(target=loop)
    worker.start()
    while not driver._loops:
        time.sleep(0.001)
    charged = []
    for i in range(1, 31):
        driver.handle(_tick(0.01 * i), None)
        charged += [ack.compute for ack in acks.take()]
    done.set()
    worker.join(10)
    acks.close()
    assert len(charged) == 30  # every tick answered
    stepped = [i for i, c in enumerate(charged) if c > 0]
    assert stepped == [10, 20], charged  # ticks 0.11 and 0.21 released a step each ...
    assert all(charged[i] >= 0.029 for i in stepped), charged  # ... and answered with its CPU


def test_a_tick_never_waits_for_a_loop_that_ended_or_was_cancelled(driver):
    cancelled = threading.Event()
    pacer = Pacer(0.1, driver=driver)
    waiting = threading.Thread(target=lambda: pacer.wait(cancelled.is_set))
    waiting.start()
    while not driver._loops:
        time.sleep(0.001)
    cancelled.set()  # e.g. the action's goal was cancelled while it waited for its period
    waiting.join(10)
    assert not waiting.is_alive() and not driver._loops
    # A loop whose thread ended without closing its pacer (a bug in the action): the tick goes on.
    forgetful = Pacer(0.1, driver=driver)

    def step_then_return() -> None:
        forgetful.wait()  # joins, waits for its period; then its thread ends in the middle of a step

    t = threading.Thread(target=step_then_return)
    t.start()
    while len(driver._loops) < 1:
        time.sleep(0.001)
    for i in range(1, 31):
        driver.handle(_tick(0.01 * i), None)  # released at 0.11; the thread ends; later ticks go on
    t.join(10)
    assert not t.is_alive()
    assert not driver._loops  # the tick that found it gone let it go


# -- a step worker held by the driver: its steps belong to the tick that triggered them ------------------
def _spin_cpu(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_a_held_worker_finishes_the_ticks_steps_before_the_answer_which_carries_their_cpu(driver):
    """A detector hands each frame to its worker thread. Under lockstep, the tick that brought the
    frame is answered only once the worker has detected it (and published), with the worker's CPU
    in the answer: the simulator must not run on while the detector is busy, or which frames get
    detected depends on the machine's speed."""
    from emos.core.clock import ack_topic
    from emos.core.offload import StepWorker
    from emos.msgs import LockstepAck
    from emos.transport.pubsub import Subscriber

    acks = Subscriber(driver.ctx, ack_topic("follower"), LockstepAck, queue_size=64)
    detector = StepWorker("detector", "latest")
    detector.start()
    driver.hold_ticks_for(detector)
    detected: list[int] = []
    answered_after: list[int] = []
    charged: list[float] = []
    try:
        for i in range(1, 11):
            frame = i

            def detect(frame: int = frame) -> None:
                _spin_cpu(0.02)
                detected.append(frame)

            assert detector.submit(detect, step=True)  # what Vision's step does with a frame
            driver.handle(_tick(0.01 * i), None)
            answered_after.append(len(detected))
            charged += [ack.compute for ack in acks.take()]
    finally:
        driver.release_ticks_from(detector)
        detector.stop()
        acks.close()
    assert detected == list(range(1, 11))  # every frame, none replaced by a newer one
    assert answered_after == list(range(1, 11))  # each answer came after that tick's frame was done
    assert len(charged) == 10 and all(c >= 0.019 for c in charged), charged


def test_housekeeping_jobs_and_released_workers_do_not_hold_ticks(driver, caplog):
    """A reconnect to a model server (not a step) may block for seconds: the tick goes on. A step
    that overruns the wait is reported by name and the tick is answered without it."""
    from emos.core.offload import StepWorker

    worker = StepWorker("detector", "queue")
    worker.start()
    driver.hold_ticks_for(worker)
    gate = threading.Event()
    try:
        worker.submit(gate.wait)  # housekeeping, blocking until the test lets it go
        assert worker.wait_steps(0)  # no step waiting or running: nothing for a tick to wait for
        driver.handle(_tick(0.01), None)
        assert not gate.is_set() and worker.busy  # answered while the housekeeping job still runs
        gate.set()
        assert worker.wait_idle(10)

        gate.clear()
        worker.submit(gate.wait, step=True)  # a step stuck on something outside the run
        driver.STEP_WAIT_S = 0.05  # the instance's bound: the test need not wait 5 s
        with caplog.at_level("WARNING", logger="emos.clock"):
            driver.handle(_tick(0.02), None)
        assert "step worker detector did not finish its steps" in caplog.text
        gate.set()
        assert worker.wait_steps(10)

        driver.release_ticks_from(worker)
        gate.clear()
        worker.submit(gate.wait, step=True)
        driver.handle(_tick(0.03), None)  # released: the tick does not wait for its step
        assert worker.busy
    finally:
        gate.set()
        worker.stop()


def test_replaced_and_dropped_steps_are_not_waited_for():
    """A ``latest`` worker replaces a waiting frame with a newer one; ``stop`` drops the waiting
    jobs: neither may leave a step counted that will never run (a tick would wait for it)."""
    from emos.core.offload import StepWorker

    worker = StepWorker("camera", "latest")
    worker.start()
    gate = threading.Event()
    done: list[int] = []
    worker.submit(gate.wait, step=True)
    while not worker.busy or worker.pending:
        time.sleep(0.001)
    for i in range(5):
        worker.submit(lambda i=i: done.append(i), step=True)  # each replaces the one before
    assert worker.dropped == 4 and not worker.wait_steps(0)
    gate.set()
    assert worker.wait_steps(10) and done == [4]
    gate.clear()
    worker.submit(gate.wait, step=True)
    while worker.pending:
        time.sleep(0.001)
    worker.submit(lambda: done.append(5), step=True)
    stopper = threading.Thread(target=worker.stop)
    stopper.start()
    while worker.pending:  # stop drops the waiting step at once ...
        time.sleep(0.001)
    gate.set()  # ... and lets the running one end
    stopper.join(10)
    assert worker.wait_steps(0) and done == [4]
