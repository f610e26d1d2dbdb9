"""One clock for every component: wall time, or the simulator's time when a Simulator runs.

``now()`` is what component code reads instead of ``time.time()``. It returns:

- in a node whose config has ``use_sim_time=True``: the last ``/clock`` time that node saw;
- otherwise, if a Simulator publishes ``/clock`` in this run: its latest time (looked up
  lazily; a missing publisher is looked for again at most once per second);
- otherwise the wall clock.

Lockstep. A Simulator in ``clock_mode="lockstep"`` publishes ``/clock`` and then waits until
every component it lists in ``lockstep_consumers`` has *answered* that tick on
``/clock_ack/<component>``. A node with ``use_sim_time`` answers (a ``LockstepAck``: the tick, and the CPU time its steps
took since its previous answer) after it has handled the tick:
a Timed component runs its step on simulated time (every ``1/loop_rate`` simulated seconds)
and then answers; other run types answer once the inputs that arrived with the tick are
handled. Everything the simulator published for a tick is on its rings before the ``/clock``
message, and a consumer publishes its outputs before its answer, so a consumer always sees
the whole tick and the simulator always sees the consumer's command: on a loaded machine
only the wall time changes. (Pipelines of several consumers in one tick are ordered only by
the order of their answers; put the stage that must see another's output in the next tick.)
"""
from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from emos.msgs.std import Time
    from emos.transport.context import RunContext
    from emos.transport.waker import Waker

CLOCK_TOPIC = "/clock"
ACK_PREFIX = "/clock_ack/"
_RESCAN_S = 1.0

log = logging.getLogger("emos.clock")


def ack_topic(component_name: str) -> str:
    """The topic on which ``component_name`` answers lockstep ticks."""
    return f"{ACK_PREFIX}{component_name}"


def _lock() -> threading.Lock:
    return threading.Lock()


_state_lock = _lock()
_driven_time: float | None = None  # set by SimTimeDriver: the newest tick a sim-time node saw
_follower: _PassiveFollower | None = None


def now() -> float:
    """Seconds: simulated time when a simulator drives this process, else ``time.time()``."""
    if _driven_time is not None:
        return _driven_time
    follower = _passive_follower()
    t = follower.time() if follower is not None else None
    return t if t is not None else time.time()


def stamp() -> Time:
    """``now()`` as a message stamp (a ``builtin_interfaces/Time``): what a component puts in the
    headers it publishes, so the stamps it writes and the ages others compute with ``now()`` are
    on one clock (simulated seconds when a simulator drives the run). ``Time.now()`` is the wall
    clock, for stamps that other processes compare with wall time (the component status)."""
    from emos.msgs.std import Time as _Time  # lazily, as the other message imports here

    t = sim_time()
    return _Time.now() if t is None else _Time.from_sec(t)  # the wall clock to the nanosecond


def release_driven_time() -> None:
    """Forget the simulated time a ``SimTimeDriver`` of this process set: ``now()`` reads the
    wall clock (or a simulator of the run) again. For a process that drove a node on a clock of
    its own and goes on without it (``emos.testing``)."""
    global _driven_time
    with _state_lock:
        _driven_time = None


def sim_time() -> float | None:
    """Simulated time if this process follows a simulator's clock, else None."""
    if _driven_time is not None:
        return _driven_time
    follower = _passive_follower()
    return follower.time() if follower is not None else None


def run_clock(ctx: RunContext) -> _PassiveFollower:
    """A reader of the simulated clock of run ``ctx`` for a process that is no node (the
    supervisor): ``.time()`` is the newest ``/clock`` time, None while no simulator publishes it."""
    return _PassiveFollower(ctx)


def _passive_follower() -> _PassiveFollower | None:
    global _follower
    if _follower is None:
        from emos.transport.context import RunContext

        ctx = RunContext.from_env()
        if ctx is None:
            return None  # not inside a run: there is no simulator to follow
        with _state_lock:
            if _follower is None:
                _follower = _PassiveFollower(ctx)
    return _follower


class _PassiveFollower:
    """Reads the newest ``/clock`` message of the run when asked (no wake-ups, no answers)."""

    def __init__(self, ctx: RunContext) -> None:
        self.ctx = ctx
        self._sub: Any = None
        self._last_look = 0.0
        self._time: float | None = None
        self._lock = threading.Lock()

    def time(self) -> float | None:
        with self._lock:
            if self._sub is None:
                if time.monotonic() - self._last_look < _RESCAN_S:
                    return self._time
                self._last_look = time.monotonic()
                from emos.msgs import Clock
                from emos.transport.pubsub import Subscriber

                # transient_local: the first read is the newest tick already published, not None
                # until the next one (now() would read the wall clock in between).
                sub = Subscriber(self.ctx, CLOCK_TOPIC, Clock, queue_size=1, transient_local=True)
                if not sub.publishers():
                    sub.close()
                    return self._time
                self._sub = sub
            msg = self._sub.latest()
            if msg is not None:
                self._time = msg.clock.to_sec()
            return self._time


class SimTimer:
    """A periodic callback on simulated time: the timers a ``use_sim_time`` component creates
    (``create_timer``) fire on the ticks of ``/clock``, as ROS 2 timers follow a node's clock.
    A wall-clock timer would not: under lockstep, a DriveManager whose 20 Hz watchdog plays a
    back-out step by step drove it for 1/20 *wall* s per step, 5x too short on a machine that
    slowed the simulator 5x and 3x too long (beyond the distance checked against the scan) on
    an idle one that runs it 3x faster than real time. Missed periods are skipped, not queued.
    The first tick after creation arms it; a callback's exception is logged (rate-limited) and
    the tick is still answered."""

    def __init__(self, driver: SimTimeDriver, period: float, callback: Callable[[], Any], name: str = "") -> None:
        if not period > 0:
            raise ValueError(f"timer period must be > 0 s, got {period}")
        from emos.ratelimit import RateLimitedLog

        self.period, self.callback, self.name = period, callback, name
        self._driver: SimTimeDriver | None = driver
        self._next: float | None = None
        self._errors = RateLimitedLog(log, interval=5.0)
        driver.timers.append(self)

    def fire_due(self, t: float) -> None:
        if self._next is None or t < self._next - 2 * self.period:
            self._next = t + self.period  # armed now (or time went back: the simulator restarted)
            return
        if t < self._next - 1e-9:
            return
        try:
            self.callback()
        except Exception as exc:
            self._errors.exception(exc, f"[{self.name}] timer")
        while self._next <= t + 1e-9:
            self._next += self.period

    def cancel(self) -> None:
        if self._driver is not None:
            if self in self._driver.timers:
                self._driver.timers.remove(self)
            self._driver = None


class SimTimeDriver:
    """Drives one node on simulated time and answers its ticks (used by ``Node`` when the
    component's config has ``use_sim_time``)."""

    def __init__(self, ctx: RunContext, name: str, waker: Waker, period: Callable[[], float]) -> None:
        from emos.msgs import Clock, LockstepAck
        from emos.transport.pubsub import Publisher, Subscriber

        self.name = name
        self._period = period
        self._ack_cls = LockstepAck
        self.sub = Subscriber(ctx, CLOCK_TOPIC, Clock, waker=waker, queue_size=64)
        self.pub = Publisher(ctx, ack_topic(name), LockstepAck, publisher_id=name, depth=8)
        self.compute_s = 0.0  # thread CPU seconds of the node's steps since its last answer (Node._run_step adds)
        self.time: float | None = None
        self.timers: list[SimTimer] = []  # the component's create_timer timers, on simulated time
        self._published: deque[tuple[int, float]] = deque(maxlen=512)  # (publish stamp ns, simulated time) of recent ticks
        self._next_step: float | None = None
        self.ticks = 0
        # Action loops in threads of their own, stepped inside the tick (``Pacer``): the node
        # thread adds and reads them, action threads join and leave.
        self._loops: list[_SteppedLoop] = []
        self._loops_lock = threading.Lock()
        self._loop_waits: Any = None  # a RateLimitedLog, made on the first overlong step
        # Step workers whose steps belong to the tick that triggered them (hold_ticks_for).
        self._workers: list[Any] = []

    def has_news(self) -> bool:
        return self.sub.has_news()

    def take(self) -> Any | None:
        """The newest new tick (a ``Clock``), or None. Taken *before* the node's inputs, so
        every message published before that tick is visible when the inputs are read."""
        items = self.sub.take_with_info()
        if not items:
            return None
        for msg, stamp_ns, _ in items:
            self._published.append((stamp_ns, msg.clock.to_sec()))
        self.ticks += len(items)
        self.time = items[-1][0].clock.to_sec()  # the node is at this tick while it handles its inputs
        return items[-1][0]

    def time_at(self, stamp_ns: int) -> float | None:
        """Simulated time of the newest tick published before wall time ``stamp_ns``: a message's
        age on the simulated clock, the same however late this node woke to read it. Older than
        every tick remembered: the oldest one's time (its age is at least that much)."""
        for published_ns, t in reversed(self._published):
            if published_ns <= stamp_ns:
                return t
        return self._published[0][1] if self._published else None

    def handle(self, tick: Any, run_step: Callable[[], None] | None, answer: bool = True) -> None:
        """Run the Timed step if one is due at ``tick`` (``run_step`` None: not a Timed
        component, or not active), then answer the tick. ``answer=False``: only follow the
        time (a node that has not been active yet: see ``Node._take_inputs``)."""
        global _driven_time
        t = tick.clock.to_sec()
        self.time = t
        with _state_lock:
            _driven_time = t
        if not answer:
            return
        if run_step is not None:
            if self._next_step is None or t < self._next_step - 2 * self._period():
                self._next_step = t  # the first tick, or time went back (the simulator restarted)
            if t >= self._next_step - 1e-9:
                run_step()
                period = self._period()
                while self._next_step <= t + 1e-9:  # one step per due tick; missed periods are skipped
                    self._next_step += period
        else:
            self._next_step = None
        if self.timers:
            cpu0 = time.thread_time()
            for timer in list(self.timers):  # before the answer: the simulator sees what they publish
                timer.fire_due(t)
            self.compute_s += time.thread_time() - cpu0  # a timer's work is the stack's compute too
        if self._loops:
            self._step_loops(t)
        if self._workers:
            self._wait_for_workers(t)
        self.pub.publish(self._ack_cls(clock=tick.clock, compute=self.compute_s))
        self.compute_s = 0.0

    # -- work in other threads, done inside the tick ---------------------------------------------------
    STEP_WAIT_S = 5.0  # wall seconds: only a step that blocks on something outside the run takes that long

    def hold_ticks_for(self, worker: Any) -> None:
        """Answer each tick only once ``worker`` (a ``StepWorker``) has finished the steps the
        tick's inputs gave it, and charge their CPU: a detector that hands its frames to a
        worker thread then sees every frame of a lockstep run, however slow the machine, as a
        Timed step would. Without this the simulator ran on while the worker was busy, and
        which frames were detected (and so where the robot went) depended on the machine."""
        if worker not in self._workers:
            self._workers.append(worker)

    def release_ticks_from(self, worker: Any) -> None:
        if worker in self._workers:
            self._workers.remove(worker)

    def _wait_for_workers(self, t: float) -> None:
        for worker in list(self._workers):
            finished = worker.wait_steps(self.STEP_WAIT_S)
            self.compute_s += worker.take_cpu()
            if not finished:
                self._step_warning("worker-step", "[%s] the step worker %s did not finish its steps within %.0f s of the "
                                    "tick at %.3f s; answering the tick without them", self.name, worker.name,
                                    self.STEP_WAIT_S, t)

    def _step_warning(self, key: str, message: str, *args: Any) -> None:
        if self._loop_waits is None:
            from emos.ratelimit import RateLimitedLog

            self._loop_waits = RateLimitedLog(log, interval=10.0)
        self._loop_waits.warning(key, message, *args)

    def join_loop(self, period: float) -> _SteppedLoop:
        """Register the calling thread's loop: from the next due tick on, it steps inside ticks."""
        loop = _SteppedLoop(period, threading.current_thread(), self.time)
        with self._loops_lock:
            self._loops.append(loop)
        return loop

    def leave_loop(self, loop: _SteppedLoop) -> None:
        loop.left = True
        loop.done.set()  # a tick waiting for this loop's step goes on
        with self._loops_lock:
            if loop in self._loops:
                self._loops.remove(loop)

    def _step_loops(self, t: float) -> None:
        """Let each action loop whose period is due at ``t`` take one step, and wait until it has,
        so the simulator sees its command with this tick's answer and charges its compute."""
        with self._loops_lock:
            loops = list(self._loops)
        for loop in loops:
            if not loop.due(t):
                continue
            loop.done.clear()
            loop.go.set()
            waited = 0.0
            while not loop.done.wait(0.05):
                waited += 0.05
                if loop.left or not loop.thread.is_alive() or waited >= self.STEP_WAIT_S:
                    break
            self.compute_s += loop.take_cpu()
            if loop.done.is_set() or loop.left:
                continue
            if not loop.thread.is_alive():  # it ended without closing its Pacer: no tick waits for it again
                self.leave_loop(loop)
                self._step_warning("loop-gone", "[%s] an action loop (thread %s) ended without closing its Pacer",
                                    self.name, loop.thread.name)
            else:
                self._step_warning("loop-step", "[%s] an action loop (thread %s) did not finish its step within %.0f s "
                                    "of the tick at %.3f s; answering the tick without it", self.name,
                                    loop.thread.name, self.STEP_WAIT_S, t)

    def close(self) -> None:
        self.sub.close()
        self.pub.close()


class _SteppedLoop:
    """One action loop stepped by a ``SimTimeDriver``: the node thread sets ``go`` when the
    loop's period is due and waits for ``done``; the loop's thread steps between the two."""

    def __init__(self, period: float, thread: threading.Thread, joined_at: float | None) -> None:
        self.period, self.thread = period, thread
        self.go, self.done = threading.Event(), threading.Event()
        self.done.set()  # not stepping
        self.left = False
        self._next = None if joined_at is None else joined_at + period
        self._cpu = 0.0
        self._cpu0: float | None = None

    def due(self, t: float) -> bool:
        if self._next is None or t < self._next - 2 * self.period:
            self._next = t + self.period  # the first tick seen, or time went back (a restarted simulator)
            return False
        if t < self._next - 1e-9:
            return False
        while self._next <= t + 1e-9:  # one step per due tick; missed periods are skipped
            self._next += self.period
        return True

    def started(self) -> None:
        self._cpu0 = time.thread_time()

    def finished(self) -> None:
        if self._cpu0 is not None:
            self._cpu += time.thread_time() - self._cpu0  # the loop thread's CPU, read in that thread
            self._cpu0 = None
        self.done.set()

    def take_cpu(self) -> float:
        cpu, self._cpu = self._cpu, 0.0
        return cpu


class Pacer:
    """Paces a loop that runs in its own thread (an action's loop) at ``period`` seconds of the
    node's clock. A loop that slept ``period`` of wall time stepped 3 times per simulated period
    on a machine that slowed the simulator 3x, and its algorithm, which takes each step to be
    ``period`` long, misjudged the target's speed (the vision follower lost the person).

    In a node on simulated time (``driver``: its ``SimTimeDriver``, from ``Node.pacer``), the
    loop steps *inside* the node's ticks: ``wait()`` returns when a tick makes a period due, and
    the node answers that tick only after the loop's next ``wait()`` (its step done), so a
    lockstep simulator sees the loop's command and charges its compute like a Timed step's.
    Without a driver it reads ``now`` (the wall clock, or a simulator's time followed
    passively). Missed periods are skipped, not caught up; time that goes back (a restarted
    simulator) restarts the pacing. Call ``close()`` (or use ``with``) when the loop ends, so a
    tick never waits for a loop that is gone. ``now``: the clock to read (tests give their own)."""

    POLL_S = 0.002  # wall seconds between two readings of a simulated clock
    CANCEL_POLL_S = 0.02  # wall seconds between two looks at ``cancelled`` while waiting for a tick

    def __init__(self, period: float, now: Callable[[], float] | None = None, driver: SimTimeDriver | None = None) -> None:
        if not period > 0:
            raise ValueError(f"Pacer period must be > 0 s, got {period}")
        self.period = period
        self._now = now or globals()["now"]
        self._next: float | None = None
        self._driver = driver
        self._loop: _SteppedLoop | None = None

    def __enter__(self) -> Pacer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """The loop has ended: ticks no longer wait for it."""
        if self._loop is not None and self._driver is not None:
            self._driver.leave_loop(self._loop)
        self._loop = None

    def wait(self, cancelled: Callable[[], bool] = lambda: False) -> None:
        """Return once the next period has begun (or at once when ``cancelled()``)."""
        if self._driver is not None:
            self._wait_for_tick(self._driver, cancelled)
            return
        t = self._now()
        if self._next is None or t < self._next - 2 * self.period:
            self._next = t
        self._next += self.period
        while (t := self._now()) < self._next - 1e-9:
            if cancelled():
                return
            # On the wall clock one sleep does; a simulated clock is read again every POLL_S.
            time.sleep(self._next - t if sim_time() is None and self._now is now else self.POLL_S)
        if t >= self._next + self.period:
            self._next = t  # late by more than a period: skip what was missed

    def _wait_for_tick(self, driver: SimTimeDriver, cancelled: Callable[[], bool]) -> None:
        loop = self._loop
        if loop is None:
            loop = self._loop = driver.join_loop(self.period)
        else:
            loop.finished()  # the step since the last wait: the tick that released it may answer now
        while not loop.go.wait(self.CANCEL_POLL_S):
            if cancelled():
                self.close()
                return
        loop.go.clear()
        loop.started()
