"""Process mode of ``emos bench barn``: one supervised system per world (``emos run`` of the
recipe :mod:`.stack` generates), scored by a referee that lives in the harness only.

The referee reads the Simulator's ground-truth output (true pose after every physics tick) and
its ``sim_status`` (the sticky collision flag) over the component's control socket; nothing of
either reaches the navigation stack. It judges with the protocol's ``TrialMonitor`` (official
timer from the first 0.1 m of motion), on simulated time counted from when the goal is given
(the stack's start-up, before it has a goal, is not the robot's driving time).
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import attrs

from emos.actors.sim.barn_protocol import TrialMonitor
from emos.actors.sim.barn_trial import start_and_goal
from emos.actors.sim.barn_worlds import BarnWorld
from emos.actors.sim.dynabarn import DynaWorld
from emos.core.prctl import die_with
from emos.errors import EmosError
from emos.supervisor.launched import SystemFailed, log_tail, wait_active, wait_run_dir

from .harness import EpisodeResult, score_run
from .stack import GOAL_TOPIC, GROUND_TRUTH_TOPIC, LOCALIZED_POSE_TOPIC, NAV_COMPONENTS, PLAN_TOPIC, SIM_NAME, StackOptions, recipe_source


class TrialAbandoned(EmosError, RuntimeError):
    """The benchmark is being stopped: this trial's system was stopped too, and it has no result
    (unlike a system failure, which counts as a failed trial)."""


class TrialSystems:
    """The trial systems in flight of one benchmark run, so that stopping the run (Ctrl-C,
    SIGTERM) stops them at once instead of waiting for each trial to finish."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._live: set[subprocess.Popen] = set()
        self._stopping: list[threading.Thread] = []  # teardowns of finished trials still going on
        self.abandoned = threading.Event()

    def started(self, proc: subprocess.Popen) -> None:
        with self._lock:
            self._live.add(proc)
        if self.abandoned.is_set():  # abandoned while this one was being spawned
            proc.terminate()

    def ended(self, proc: subprocess.Popen) -> None:
        with self._lock:
            self._live.discard(proc)

    def abandon(self) -> None:
        """Stop every system in flight (SIGTERM: each supervisor stops its components in order);
        their referees then end with :class:`TrialAbandoned`, and no new trial starts."""
        self.abandoned.set()
        with self._lock:
            live = list(self._live)
        for proc in live:
            if proc.poll() is None:
                proc.terminate()

    def stop_later(self, teardown: Callable[[], None], name: str) -> None:
        """Run ``teardown`` (stop a finished trial's system, keep its log, remove its files) in a
        thread, so that the next trial starts while this one's supervisor stops its components
        one by one (0.4 s on an idle machine, 2-3 s beside other work): the result is known
        before. :meth:`wait_stopped` waits for every one of them."""
        thread = threading.Thread(target=teardown, name=f"barn-teardown-{name}")
        with self._lock:
            self._stopping = [t for t in self._stopping if t.is_alive()]
            self._stopping.append(thread)
        thread.start()

    def wait_stopped(self) -> None:
        """Return once every teardown handed to :meth:`stop_later` has finished (each ends: a
        system that does not stop on SIGTERM is killed after 30 s)."""
        with self._lock:
            stopping, self._stopping = self._stopping, []
        for thread in stopping:
            thread.join()


STARTUP_TIMEOUT_S = 120.0  # wall: a loaded 2-core machine starts six processes slowly
COLLISION_POLL_S = 0.2  # wall: how often the referee asks the simulator about contacts
# wall: the referee's pause between reads of its topics. It only watches (the simulator does not
# wait for it) and its queues hold every true pose of 40 simulated seconds, so a longer pause
# loses nothing; at 5 ms its loop took 1.3-2.8 s of CPU time per trial, as much as a navigation
# component, on the cores the trial's own processes need.
REFEREE_POLL_S = 0.05


def run_episode_process(entry: BarnWorld | DynaWorld, opts: StackOptions, wall_timeout: float = 600.0,
                        keep_log: Path | None = None, png_path: Path | None = None,
                        systems: TrialSystems | None = None,
                        observer: Callable[[Any], Callable[[], None]] | None = None,
                        keep_log_on_success: bool = True, stop_in_background: bool = False) -> EpisodeResult:
    """Run one world through the processes and score it under ``opts.rules``; with ``png_path``,
    draw the run there (the true path the referee saw, the stack's last plan, the contacts).
    ``keep_log``: copy the system's log there (``keep_log_on_success=False``: only if the trial
    did not succeed, or had no result).
    ``systems``: the run's trials in flight; once it is abandoned the trial raises
    :class:`TrialAbandoned` (before it starts, or as soon as its stopped system is noticed).
    ``stop_in_background`` (with ``systems``): return the result as soon as it is known and stop
    the system in a thread of ``systems`` (:meth:`TrialSystems.wait_stopped` waits for it); a
    trial without a result stops its system before raising, as always.
    ``observer``: called with the trial's ``RunContext`` once its system is up (to subscribe to
    its topics: ``scripts/barn_pose_replay.py``); it returns what to call when the trial ends."""
    background = stop_in_background and systems is not None
    systems = systems or TrialSystems()
    if systems.abandoned.is_set():
        raise TrialAbandoned(f"world {entry.idx} seed {opts.seed}: not started, the benchmark is stopping")
    wall0 = time.perf_counter()
    seen = _Seen() if png_path is not None else None
    tmp = Path(tempfile.mkdtemp(prefix=f"emos-barn-{entry.idx}-"))
    log_path = tmp / "system.log"
    proc: subprocess.Popen | None = None

    def teardown(keep: bool) -> None:
        try:
            if proc is not None:
                _stop(proc)
            if keep and keep_log is not None and log_path.exists():
                keep_log.write_bytes(log_path.read_bytes())
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    try:
        recipe = tmp / "barn_recipe.py"
        recipe.write_text(recipe_source(opts))
        with open(log_path, "wb") as log:
            benchmark = os.getpid()

            def die_with_the_benchmark() -> None:  # in the child, before exec
                if not die_with(benchmark):
                    os._exit(1)

            # A benchmark killed from outside runs no `finally`: its trial's system must not go on
            # without it (one did, holding its shared memory, until stopped by hand).
            proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(recipe)], stdout=log,
                                    stderr=subprocess.STDOUT, cwd=tmp, preexec_fn=die_with_the_benchmark)
        systems.started(proc)
        try:
            outcome = _referee(proc, log_path, entry, opts, wall_timeout, seen, observer)
        finally:
            systems.ended(proc)
    except BaseException as exc:  # no result (Ctrl-C included): stop the system now; its log says why
        teardown(keep=True)
        if isinstance(exc, Exception) and systems.abandoned.is_set():  # whatever the stopped system made the referee see
            raise TrialAbandoned(f"world {entry.idx} seed {opts.seed}: stopped with the benchmark") from None
        raise
    reached, collided, t, distance, reason, misses = outcome
    result = score_run(entry, reached, collided, t, opts.rules)
    # wall_s: to the result; the system's stop (ordered, component by component) comes after.
    result = attrs.evolve(result, seed=opts.seed, distance_m=distance, wall_s=time.perf_counter() - wall0, reason=reason,
                          deadline_misses=misses)
    keep = keep_log_on_success or not result.success
    if background:
        systems.stop_later(lambda: teardown(keep), f"{entry.idx}-{opts.seed}")
    else:
        teardown(keep)
    if seen is not None and png_path is not None:
        _draw(entry, opts, result, seen, png_path)
    return result


@attrs.define
class _Seen:
    """What the referee saw of a run, for its picture: true poses, the poses the stack believed,
    the last plan, contacts."""

    poses: list[tuple[float, float, float]] = attrs.field(factory=list)
    believed: list[tuple[float, float]] = attrs.field(factory=list)
    last_stamp: float | None = None  # simulated time of the last true pose: where the movers are drawn
    plan: Any = None
    contacts: list[list[float]] = attrs.field(factory=list)


def _draw(entry: BarnWorld | DynaWorld, opts: StackOptions, result: EpisodeResult, seen: _Seen, png_path: Path) -> None:
    """The run's top-down picture, drawn as an in-process run's is (same world, same window)."""
    import numpy as np

    from emos.actors.sim.barn_trial import build_trial
    from emos.actors.sim.render import render_topdown

    from .harness import picture_bounds, picture_title

    trial = build_trial(entry, opts.seed, opts.rules)  # the same world, rebuilt here only to be drawn
    try:
        robot = trial.robot
        if seen.poses:
            robot.trail = [(x, y) for x, y, _ in seen.poses]
            robot.pose = np.asarray(seen.poses[-1], dtype=float)
        robot.collided = result.collided
        robot.contacts = [_Contact((float(x), float(y), 0.0)) for x, y in seen.contacts]
        render_topdown(trial.world, png_path, plan=seen.plan, goal=trial.goal, goal_radius=opts.rules.goal_radius,
                       bounds=picture_bounds(entry), pixels_per_m=40,
                       title=picture_title(trial, result, f"{opts.algorithm} (processes)"), at_time=seen.last_stamp,
                       estimate=seen.believed or None)
    finally:
        trial.close()


@attrs.frozen
class _Contact:
    position: tuple[float, float, float]


def _referee(proc: subprocess.Popen, log_path: Path, entry: BarnWorld | DynaWorld, opts: StackOptions,
             wall_timeout: float, seen: _Seen | None = None,
             observer: Callable[[Any], Callable[[], None]] | None = None) -> tuple[bool, bool, float, float, str, int]:
    from emos import msgs as M
    from emos.core.reconfig import ComponentServices
    from emos.core.rpc import RpcClient
    from emos.transport.context import RunContext
    from emos.transport.pubsub import Publisher, Subscriber

    rules = opts.rules
    run_dir = wait_run_dir(proc, log_path, f"world {entry.idx}", STARTUP_TIMEOUT_S)
    ctx = RunContext(run_dir.name, run_dir, owner=False)
    with RpcClient(run_dir / "supervisor.sock") as rpc:
        wait_active(rpc, proc, log_path, (SIM_NAME, *NAV_COMPONENTS), f"world {entry.idx}", STARTUP_TIMEOUT_S)
    truth = Subscriber(ctx, GROUND_TRUTH_TOPIC, M.Odometry, queue_size=4096)
    # What the stack believes, to say how far off it was when a trial times out (a robot that
    # waits outside the goal circle usually thinks it is inside) and to draw it.
    believed = Subscriber(ctx, LOCALIZED_POSE_TOPIC, M.Odometry, queue_size=4096)
    drift = _PoseDrift()
    stop_observing = observer(ctx) if observer is not None else None
    plans = Subscriber(ctx, PLAN_TOPIC, M.Path, queue_size=4) if seen is not None else None
    goal_pub = Publisher(ctx, GOAL_TOPIC, M.PointStamped, publisher_id="barn_referee")
    sim = ComponentServices(SIM_NAME, ctx)
    start, goal_xy = start_and_goal(entry)
    monitor = TrialMonitor(start[:2], goal_xy, rules.goal_radius, rules.time_limit)

    def sim_status() -> dict:
        return _sim_status(sim, f"world {entry.idx}", log_path)
    try:
        t0 = _latest_stamp(truth, proc, log_path)  # the trial starts when the goal is given
        goal = M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=goal_xy[0], y=goal_xy[1]))
        last_xy: tuple[float, float] | None = None
        last_motion = (0.0, 0.0)  # true (v, omega) of the last moving tick: what a collision was caused by
        last_t = 0.0
        distance = 0.0
        goal_sent = 0.0
        next_poll = 0.0
        deadline = time.monotonic() + wall_timeout
        while True:
            now = time.monotonic()
            if now - goal_sent > 1.0:  # repeated: a subscriber that joined late still gets it
                goal.header.stamp = M.Time.from_sec(t0)
                goal_pub.publish(goal)
                goal_sent = now
            collided = False
            if now >= next_poll:
                status = sim_status()
                collided = bool(status.get("collided"))
                next_poll = now + COLLISION_POLL_S
            for msg in truth.take():
                t = msg.header.stamp.to_sec()
                if t < t0:
                    continue
                p = msg.pose.pose.position
                xy = (p.x, p.y)
                moving = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)
                if abs(moving[0]) > 1e-3 or abs(moving[1]) > 1e-3:  # a contact zeroes the twist: keep the last motion
                    last_motion = moving
                if last_xy is not None:
                    distance += math.dist(xy, last_xy)
                last_xy, last_t = xy, t - t0
                drift.truth(t, xy)
                if seen is not None:
                    seen.last_stamp = t
                    seen.poses.append((p.x, p.y, msg.pose.pose.orientation.yaw()))
                outcome = monitor.update(last_t, xy, False)
                if outcome is not None:
                    break
            for msg in believed.take():
                p = msg.pose.pose.position
                drift.believed(msg.header.stamp.to_sec(), (p.x, p.y))
                if seen is not None and msg.header.stamp.to_sec() >= t0:  # the trial's, as the true trail
                    seen.believed.append((p.x, p.y))
            if monitor.outcome is None and collided:
                monitor.update(last_t, last_xy or start[:2], True)
            if plans is not None and seen is not None:  # plans is subscribed only when seen is kept
                plan = plans.latest()
                if plan is not None and plan.poses:
                    seen.plan = [(ps.pose.position.x, ps.pose.position.y) for ps in plan.poses]
            outcome = monitor.outcome
            if outcome is not None:
                final = sim_status()
                contacts = final.get("contacts") or []
                if seen is not None:
                    seen.contacts = list(contacts)
                misses = int(final.get("compute", {}).get("deadline_misses", 0))  # with the compute charged
                if outcome.reached and final.get("collided"):
                    # A touch between the last poll and the goal still fails the trial.
                    return False, True, outcome.time_s, distance, "collision (before reaching the goal)", misses
                reason = "goal" if outcome.reached else (
                    f"time limit{drift.describe()}" if outcome.timeout
                    else _collision_reason(contacts, last_xy) + _collision_cause(*last_motion))
                return outcome.reached, outcome.collided, outcome.time_s, distance, reason, misses
            if proc.poll() is not None:
                raise SystemFailed(f"world {entry.idx}: the system exited with {proc.returncode}:\n{log_tail(log_path)}")
            if now > deadline:
                raise SystemFailed(f"world {entry.idx}: no result within {wall_timeout:.0f} s wall:\n{log_tail(log_path)}")
            time.sleep(REFEREE_POLL_S)
    finally:
        truth.close()
        believed.close()
        goal_pub.close()
        if stop_observing is not None:
            stop_observing()
        if plans is not None:
            plans.close()


def _sim_status(sim: Any, what: str, log_path: Path) -> dict:
    """The Simulator's ``sim_status`` over its control socket (``sim``: its ``ComponentServices``)."""
    from emos.core.rpc import RpcConnectionError, RpcError

    try:
        return sim.execute_method("sim_status")
    except (RpcConnectionError, RpcError) as exc:
        # The Simulator's control socket failed: its process died or was killed (on a machine at
        # load 40-50 the supervisor's heartbeat watchdog killed a trial's components as hung, and
        # this error ended a 600-trial run). One broken system must not end the run: a system
        # failure, as when the system exits.
        raise SystemFailed(f"{what}: the Simulator did not answer sim_status: {exc}:\n{log_tail(log_path)}") from exc


class _PoseDrift:
    """How far the stack's pose is from the truth: its latest believed pose against the true
    pose of the same simulated time (lock-step: the truth is published every physics step, the
    belief at the mapper's rate, so a matching stamp is among the last few hundred)."""

    def __init__(self, keep: int = 512):
        self._truth: dict[float, tuple[float, float]] = {}
        self._keep = keep
        self._belief: tuple[float, tuple[float, float]] | None = None

    def truth(self, stamp: float, xy: tuple[float, float]) -> None:
        self._truth[stamp] = xy
        if len(self._truth) > 2 * self._keep:  # keep the latest: dicts keep insertion order
            for old in list(self._truth)[:self._keep]:
                del self._truth[old]

    def believed(self, stamp: float, xy: tuple[float, float]) -> None:
        self._belief = (stamp, xy)

    def error(self) -> tuple[float, tuple[float, float], tuple[float, float]] | None:
        """(metres apart, believed xy, true xy) at the latest belief, or None if either is unseen."""
        if self._belief is None or not self._truth:
            return None
        stamp, xy = self._belief
        nearest = min(self._truth, key=lambda t: abs(t - stamp))
        true_xy = self._truth[nearest]
        return math.dist(xy, true_xy), xy, true_xy

    def describe(self) -> str:
        """``'; the stack believed (x, y), 0.12 m from the true (x, y)'``, or '' if unknown."""
        err = self.error()
        if err is None:
            return ""
        dist, (bx, by), (tx, ty) = err
        return f"; the stack believed ({bx:.2f}, {by:.2f}), {dist:.2f} m from the true ({tx:.2f}, {ty:.2f})"


def _collision_cause(v: float, omega: float) -> str:
    """'; <cause> (v, omega)' from the true body twist just before a contact: ``reversing``
    (v < -0.02 m/s), ``rotation`` (|v| <= 0.05 m/s, turning), ``arc`` (driving and turning,
    |omega| > 0.05 rad/s) or ``straight``; for the collision counts by cause."""
    if v < -0.02:
        cause = "reversing"
    elif abs(v) <= 0.05 and abs(omega) > 0.05:
        cause = "rotation"
    elif abs(omega) > 0.05:
        cause = "arc"
    else:
        cause = "straight"
    return f"; {cause} (v {v:.2f} m/s, omega {omega:.2f} rad/s)"


def _collision_reason(contacts: list, last_xy: tuple[float, float] | None) -> str:
    """Where the robot first touched (as the in-process harness says it), else where it was."""
    if contacts:
        x, y = contacts[0]
        return f"collision at ({float(x):.2f}, {float(y):.2f})"
    return f"collision near ({last_xy[0]:.2f}, {last_xy[1]:.2f})" if last_xy else "collision"


def _latest_stamp(truth: Any, proc: subprocess.Popen, log_path: Path, timeout: float = 60.0) -> float:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        items = truth.take()
        if items:
            return items[-1].header.stamp.to_sec()
        if proc.poll() is not None:
            raise SystemFailed(f"the system exited with {proc.returncode}:\n{log_tail(log_path)}")
        time.sleep(0.01)
    raise SystemFailed(f"no ground truth on {GROUND_TRUTH_TOPIC} within {timeout:.0f} s:\n{log_tail(log_path)}")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
