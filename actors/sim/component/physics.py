"""The Simulator's physics thread: command in, world ticks, readings out, /clock, lockstep.

It runs beside the component's event loop in the Simulator's process, so a slow render or a
long lockstep wait never delays the status heartbeat. Everything it reads (commands, lockstep
answers) comes through its own subscribers, and it publishes through the node (thread-safe).
"""
from __future__ import annotations

import logging
import select
import threading
import time
from collections.abc import Callable
from typing import Any

from emos import msgs as M
from emos.core.clock import CLOCK_TOPIC, ack_topic
from emos.ratelimit import RateLimitedLog
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker

from ..body import SimRobot
from ..clock import ClockMode
from ..msgs import header
from ..sensors.camera import Camera
from ..sensors.lidar import Lidar
from ..sensors.odometry import Odometry
from ..sensors.wheel_imu import WheelImuOdometry
from .commands import CommandFollower, joint_targets
from .compute_charge import ComputeCharge
from .config import SimulatorConfig
from .publishing import CameraMessages, occupancy_msg, tf_tree
from .worlds import SimSetup

log = logging.getLogger("emos.sim")
# Problems that repeat every tick (lag, bad commands): the first at once, then counted per 10 s.
_limited = RateLimitedLog(log, interval=10.0)

WAIT_SLICE_S = 0.25  # lockstep: republish the tick this often while waiting (late joiners)
WARN_AFTER_S = 5.0  # lockstep: say who we wait for after this long, then every WARN_AFTER_S
MAX_LAG_S = 0.5  # realtime: further behind the wall clock than this, drop the debt instead of racing
MAP_PERIOD_S = 1.0  # the map output is republished this often (simulated s) for late subscribers


class PhysicsLoop(threading.Thread):
    """Steps ``setup.world`` until :meth:`stop`; ``publish(key, msg)`` sends an output by key."""

    def __init__(self, name: str, cfg: SimulatorConfig, setup: SimSetup, ctx: Any, inputs: dict[str, Any],
                 outputs: dict[str, type], publish: Callable[[str, Any], None], map_grid: Any | None) -> None:
        super().__init__(name=f"{name}-physics", daemon=True)
        self.cfg, self.setup, self.ctx = cfg, setup, ctx
        self.outputs, self._publish = outputs, publish
        self.map_grid = map_grid
        self.component_name = name
        # The base's own watchdog (0.25 s on the Jackal drive models) when it is the shorter.
        drive_timeout = setup.robot.drive.command_timeout if setup.robot is not None else None
        timeout = min(cfg.command_timeout, drive_timeout) if drive_timeout is not None else cfg.command_timeout
        self.follower = CommandFollower(timeout, cfg.command_array_step)
        self.lockstep = cfg.clock_mode is ClockMode.LOCKSTEP
        self._stop_event = threading.Event()
        self.error: BaseException | None = None
        self.clock_ticks = 0
        self.published: dict[str, int] = {}
        self.waited_s = 0.0  # lockstep: wall time spent waiting for answers
        self.lag_resets = 0  # realtime: how often the machine could not keep up (simulated time slowed)
        self._waker: Waker | None = None
        self._command_sub: Subscriber | None = None
        self._joint_sub: Subscriber | None = None
        self._ack_subs: dict[str, Subscriber] = {}
        self._acked: dict[str, float] = {}
        self._bad_commands = 0
        if self.lockstep:  # the lockstep wait sleeps on this; realtime polls, so needs none
            self._waker = Waker(ctx, spin_us=0.0)
        command_topic, joint_topic = inputs.get("command"), inputs.get("joint_command")
        if command_topic is not None and setup.robot is not None:
            self._command_sub = Subscriber(ctx, command_topic.name, command_topic.msg_type, waker=self._waker, queue_size=16)
        if joint_topic is not None and setup.arm is not None:
            self._joint_sub = Subscriber(ctx, joint_topic.name, joint_topic.msg_type, waker=self._waker, queue_size=16)
        if self.lockstep:
            for consumer in cfg.lockstep_consumers:
                self._ack_subs[consumer] = Subscriber(ctx, ack_topic(consumer), M.LockstepAck, waker=self._waker, queue_size=16)
                self._acked[consumer] = -1.0
        self.charge = ComputeCharge(cfg.compute_deadline, setup.world.clock.dt) if self.lockstep and cfg.compute_deadline else None
        self._delay_ticks = 0  # physics ticks the commands of the current clock tick wait (compute charge)

    # -- control -------------------------------------------------------------------------------
    def stop(self, timeout: float = 10.0) -> None:
        self._stop_event.set()
        if self.is_alive():
            self.join(timeout)
        if self.is_alive():
            log.error("[%s] physics thread did not stop within %.0f s", self.component_name, timeout)
            return
        self._close()

    def _close(self) -> None:
        for sub in [self._command_sub, self._joint_sub, *self._ack_subs.values()]:
            if sub is not None:
                sub.close()
        self._ack_subs.clear()
        self._command_sub = self._joint_sub = None
        if self._waker is not None:
            self._waker.close()
            self._waker = None

    @property
    def sim_time(self) -> float:
        return self.setup.world.clock.now()

    # -- the loop ------------------------------------------------------------------------------
    def run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # reported by the component's step as COMPONENT_FAILURE
            self.error = exc
            log.exception("[%s] physics thread failed at t=%.3f s: %s", self.component_name, self.sim_time, exc)

    def _loop(self) -> None:
        world, cfg = self.setup.world, self.cfg
        dt = world.clock.dt
        wall_start = time.monotonic()
        start_ticks = world.clock.ticks
        map_due = 0.0
        self._send_clock()
        while not self._stop_event.is_set():
            if self.lockstep and not self._wait_for_answers():
                return
            if self.charge is not None:
                self._delay_ticks = self.charge.close_tick()
            if "map" in self.outputs and self.map_grid is not None and self.sim_time >= map_due - 1e-9:
                self._send("map", occupancy_msg(self.map_grid, self.sim_time, cfg.frames.world))
                map_due += MAP_PERIOD_S
            for _ in range(cfg.ticks_per_clock):
                self._take_commands()
                if self.setup.robot is not None:
                    self.setup.robot.command(*self.follower.target(self.sim_time))
                for sensor, reading in world.step():
                    self._send_reading(sensor, reading)
                if "ground_truth" in self.outputs and self.setup.robot is not None:
                    self._send("ground_truth", self._ground_truth(self.setup.robot))
                if not self.lockstep and cfg.clock_mode is ClockMode.REALTIME:
                    target = wall_start + (world.clock.ticks - start_ticks) * dt / cfg.real_time_factor
                    delay = target - time.monotonic()
                    if delay > 0 and self._stop_event.wait(delay):
                        return
                    if delay < -MAX_LAG_S:
                        # A real world does not run faster to catch up after a stall: re-anchor.
                        wall_start -= delay
                        self.lag_resets += 1
                        _limited.warning(f"lag:{self.component_name}", "[%s] realtime: %.2f s behind the wall clock (#%d); simulated "
                                         "time slowed down instead of racing to catch up", self.component_name, -delay, self.lag_resets)
            self._send_clock()

    def _send(self, key: str, msg: Any) -> None:
        self._publish(key, msg)
        self.published[key] = self.published.get(key, 0) + 1

    def _ground_truth(self, robot: SimRobot) -> Any:
        from ..msgs import odometry_to_msg
        from ..sensors.odometry import OdometryReading

        frames = self.cfg.frames
        (x, y, yaw), (vx, vy, w) = (float(v) for v in robot.pose), (float(v) for v in robot.twist)
        return odometry_to_msg(OdometryReading(self.sim_time, frames.world, frames.robot_base, x, y, yaw, vx, vy, w))

    def _send_clock(self) -> None:
        self.clock_ticks += 1
        if "clock" in self.outputs:
            self._send("clock", M.Clock(clock=M.Time.from_sec(self.sim_time)))

    def _send_reading(self, sensor: Any, reading: Any) -> None:
        setup, frames = self.setup, self.cfg.frames
        if isinstance(sensor, (Odometry, WheelImuOdometry)):
            if "odom" in self.outputs:
                self._send("odom", reading.to_msg())
            if "tf" in self.outputs:
                assert setup.robot is not None  # odometry is measured on the robot, so there is one
                self._send("tf", tf_tree(frames, reading, setup.robot.pose, setup.lidar, setup.camera))
        elif isinstance(sensor, Lidar):
            self._send("scan", reading.to_msg())
        elif sensor is setup.wrist_camera:
            frame = CameraMessages(reading, reading.frame_id, self.cfg.jpeg_quality)
            self._send("wrist_camera", frame.for_type("camera", self.outputs["wrist_camera"]))
        elif isinstance(sensor, Camera):
            depth_frame = frames.depth if setup.robot is not None else reading.frame_id
            frame = CameraMessages(reading, depth_frame, self.cfg.jpeg_quality)
            for key in ("camera", "depth", "camera_info", "depth_camera_info", "rgbd"):
                if key in self.outputs:
                    self._send(key, frame.for_type(key, self.outputs[key]))
        elif sensor is setup.joints and "joint_states" in self.outputs:
            self._send("joint_states", M.JointState(header=header(reading.stamp, "base"), name=reading.names,
                                                    position=reading.position, velocity=reading.velocity,
                                                    effort=reading.effort))

    def _take_commands(self) -> None:
        if self._command_sub is not None:
            charge, ticks = self.charge, self.setup.world.clock.ticks
            for msg in self._command_sub.take():
                if charge is not None:
                    charge.hold(msg, ticks + self._delay_ticks)
                else:
                    self._receive(msg)
            if charge is not None and (msg := charge.due(ticks)) is not None:
                self._receive(msg)
        if self._joint_sub is not None:
            for msg in self._joint_sub.take():
                try:
                    names, positions = joint_targets(msg)
                    self.setup.arm.command(names, positions)
                    self.follower.received += 1
                except (ValueError, TypeError) as exc:  # the arm keeps its previous targets
                    self._reject(self._joint_sub.topic, exc)

    def _receive(self, msg: Any) -> None:
        try:
            self.follower.receive(msg, self.sim_time)
        except (ValueError, TypeError) as exc:
            self.follower.stop()
            assert self._command_sub is not None  # commands arrive only through it
            self._reject(self._command_sub.topic, exc)

    def _reject(self, topic: str, exc: Exception) -> None:
        self._bad_commands += 1
        _limited.error(f"command:{self.component_name}:{topic}", "[%s] rejected command #%d on %s: %s", self.component_name,
                       self._bad_commands, topic, exc)

    def _wait_for_answers(self) -> bool:
        """Lockstep: block until every consumer answered the current tick; False when stopping."""
        t = self.sim_time
        started = time.monotonic()
        warned_at = republished_at = started
        while True:
            for name, sub in self._ack_subs.items():
                for msg in sub.take():
                    self._acked[name] = max(self._acked[name], msg.clock.to_sec())
                    if self.charge is not None:
                        self.charge.report(name, msg.compute)
            pending = [n for n, at in self._acked.items() if at < t - 1e-9]
            if not pending:
                self.waited_s += time.monotonic() - started
                return True
            if self._stop_event.is_set():
                return False
            assert self._waker is not None
            ready, _, _ = select.select([self._waker.fd], [], [], WAIT_SLICE_S)
            if ready:
                self._waker.drain()
            # Measured in time, not by a quiet select: other traffic that shares the waker
            # (commands a DriveManager keeps sending) must not suppress the republish.
            if time.monotonic() - republished_at >= WAIT_SLICE_S:
                republished_at = time.monotonic()
                # Nobody answered for a while: a consumer may have joined after the tick was
                # published (subscribers only see later messages), so publish it again.
                if "clock" in self.outputs:
                    self._send("clock", M.Clock(clock=M.Time.from_sec(t)))
                if time.monotonic() - warned_at > WARN_AFTER_S:
                    warned_at = time.monotonic()
                    log.warning("[%s] lockstep: waiting %.0f s at t=%.3f s for %s to answer on %s",
                                self.component_name, warned_at - started, t, ", ".join(pending),
                                ", ".join(ack_topic(n) for n in pending))


__all__ = ["PhysicsLoop", "CLOCK_TOPIC"]
