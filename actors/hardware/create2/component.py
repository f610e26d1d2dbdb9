"""``Create2Base``: an iRobot Create 2 as an EMOS component (``/cmd_vel`` in; odometry, bumps and
battery out), with the safety that belongs at the driver.

* ``/cmd_vel`` (Twist) triggers a step: ``v +- w * 0.235 / 2`` -> Drive Direct (right, left) mm/s.
* A timer every 15 ms (the stream period) drains the checked stream frames: odometry from the
  encoder counts (``/odom``, nav_msgs-style ``Odometry``), ``/bumper`` (Bool, either bumper) and
  ``/battery`` (Float32, percent of capacity).
* Watchdog: no fresh ``/cmd_vel`` for ``cmd_timeout`` s of robot time -> one Drive Direct (0, 0),
  because the Create 2 keeps its last command forever (OI spec, Drive Direct has no timeout).
* Bump stop: while a bumper is pressed, commands that drive forward or turn are replaced by a
  stop; pure reverse (both wheels <= 0) is let through so the robot can back off the obstacle.
* Port missing/taken: activation fails with the port named. Lost mid-run: SYSTEM_FAILURE naming
  the port, a stop is attempted, and a reconnect ladder (``emos.core.retry.Backoff`` delays)
  reopens it; the stream and odometry resume (the odometry keeps its pose, re-referenced).
"""
from __future__ import annotations

import time
from typing import Any

from emos.config.base import BaseComponentConfig
from emos.core import clock
from emos.core.component import BaseComponent
from emos.core.retry import Backoff
from emos.geometry import quaternion_of_yaw
from emos.io.topic import Topic
from emos.msgs.nav import Odometry
from emos.msgs.std import Bool, Float32
from emos.ratelimit import RateLimitedLog

from . import protocol as P
from .driver import Create2Link, Create2PortError
from .odometry import DiffDriveOdometry

__all__ = ["Create2Base", "twist_to_wheels"]


def twist_to_wheels(v: float, w: float, wheel_base: float = P.WHEEL_BASE_M) -> tuple[float, float]:
    """(right, left) wheel speeds in mm/s for a body twist (m/s, rad/s)."""
    return (v + w * wheel_base / 2.0) * 1000.0, (v - w * wheel_base / 2.0) * 1000.0


class Create2Base(BaseComponent):
    """See the module docstring. ``port``: the serial device (``/dev/ttyUSB0`` or an emulator's pty)."""

    def __init__(self, *, component_name: str = "create2", port: str, cmd_timeout: float = 0.5,
                 cmd_vel: Topic | None = None, odom: Topic | None = None, bumper: Topic | None = None,
                 battery: Topic | None = None, frame_id: str = "odom", child_frame_id: str = "base_link",
                 reconnect: Backoff | None = None) -> None:
        if not isinstance(port, str) or not port:
            raise ValueError(f"component {component_name!r}: port must be a serial device path, got {port!r}")
        if not (isinstance(cmd_timeout, (int, float)) and cmd_timeout > 0):
            raise ValueError(f"component {component_name!r}: cmd_timeout must be > 0 s, got {cmd_timeout!r}")
        self.cmd_topic = cmd_vel or Topic(name="/cmd_vel", msg_type="Twist")
        self.odom_topic = odom or Topic(name="/odom", msg_type="Odometry")
        self.bumper_topic = bumper or Topic(name="/bumper", msg_type="Bool")
        self.battery_topic = battery or Topic(name="/battery", msg_type="Float32")
        super().__init__(component_name=component_name, inputs=[self.cmd_topic],
                         outputs=[self.odom_topic, self.bumper_topic, self.battery_topic],
                         config=BaseComponentConfig(loop_rate=1.0 / P.STREAM_PERIOD_S), trigger=self.cmd_topic)
        self.port = port
        self.cmd_timeout = float(cmd_timeout)
        self.frame_id, self.child_frame_id = frame_id, child_frame_id
        self.reconnect_policy = reconnect or Backoff(base=0.05, factor=2.0, cap=2.0, timeout=1e9)
        self.link: Create2Link | None = None
        self.odometry = DiffDriveOdometry()
        self.bumped = False
        self.stopped = True  # the last thing sent (or the power-on state) is "stand still"
        self._reversing = True  # the last thing sent moves no wheel forward
        self.stops_sent = 0  # watchdog and bump stops, for tests and logs
        self.stop_log: list[tuple[float, str]] = []  # (robot time, why) of each stop sent, the last 100
        self._last_frame: P.SensorFrame | None = None
        self._last_frame_time: float | None = None
        self._failures = 0
        self._next_try = 0.0
        self._log = RateLimitedLog(self._logger, interval=5.0)

    # -- lifecycle -----------------------------------------------------------------------------------
    def custom_on_activate(self) -> None:
        link = Create2Link(self.port)
        link.open()  # Create2PortError names the port: activation fails with it
        self.link = link
        self.create_timer(P.STREAM_PERIOD_S, self._poll)

    def custom_on_deactivate(self) -> None:
        if self.link is not None:
            self.link.close(stop_base=True)
            self.link = None

    custom_on_shutdown = custom_on_deactivate

    # -- commands ------------------------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        if msg is None or self.link is None:
            return
        right, left = twist_to_wheels(float(msg.linear.x), float(msg.angular.z))
        if self.bumped and not (right <= 0.0 and left <= 0.0):
            self._stop("bumper pressed")
            return
        if self.link.drive_direct(right, left):
            self.stopped = P.clamp_speed(right) == 0 and P.clamp_speed(left) == 0
            self._reversing = right <= 0.0 and left <= 0.0
        if self.link.lost is None:
            self.health_status.set_healthy()

    def _stop(self, why: str) -> None:
        if self.stopped or self.link is None:
            return
        if self.link.drive_direct(0, 0):
            self.stopped, self._reversing = True, True
            self.stops_sent += 1
            self.stop_log = [*self.stop_log[-99:], (clock.now(), why)]
            self._log.warning(("stop", why), "[%s] %s: stopping the base on %s", self.component_name, why, self.port)

    # -- sensors, watchdog, link ---------------------------------------------------------------------
    def _poll(self) -> None:
        link = self.link
        if link is None:
            return
        if link.lost is not None:
            self._recover(link)
            return
        now = clock.now()
        for frame in link.take_frames():
            dt = now - self._last_frame_time if self._last_frame_time is not None else 0.0
            self.odometry.update(frame.get(P.PKT_ENCODER_LEFT), frame.get(P.PKT_ENCODER_RIGHT), dt if dt > 0 else P.STREAM_PERIOD_S)
            self._last_frame, self._last_frame_time = frame, now
            if frame.bumped and not self.bumped:
                self.bumped = True
                self.stopped = False  # whatever it was doing, send the stop now
            elif not frame.bumped:
                self.bumped = False
        if self.bumped and not self._reversing:  # backing off the obstacle is what we want
            self._stop("bumper pressed")
        age = self.input_age(self.cmd_topic)
        if (age is None or age > self.cmd_timeout) and not self.stopped:
            self._stop(f"no {self.cmd_topic.name} for {self.cmd_timeout:g} s (watchdog)")
        if self._last_frame is not None:
            self._publish(self._last_frame)

    def _publish(self, frame: P.SensorFrame) -> None:
        odo = self.odometry
        msg = Odometry()
        msg.header.stamp = clock.stamp()
        msg.header.frame_id = self.frame_id
        msg.child_frame_id = self.child_frame_id
        msg.pose.pose.position.x, msg.pose.pose.position.y = odo.x, odo.y
        q = quaternion_of_yaw(odo.th)
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = q
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = odo.v, odo.w
        self.publish(self.odom_topic, msg)
        self.publish(self.bumper_topic, Bool(data=frame.bumped))
        capacity = frame.get(P.PKT_CAPACITY)
        self.publish(self.battery_topic, Float32(data=100.0 * frame.get(P.PKT_CHARGE) / capacity if capacity else 0.0))

    def _recover(self, link: Create2Link) -> None:
        """The reconnect ladder: SYSTEM_FAILURE naming the port, then reopen on Backoff delays."""
        if self._failures == 0:
            self.get_logger().error("[%s] %s", self.component_name, link.lost)
            if link.try_stop():  # still reachable (a read error, not a dead port): leave it standing still
                self.stopped = True
            self.health_status.set_fail_system(message=link.lost or f"Create 2 port {self.port!r} lost")
            self.health_status_publisher.publish(self.health_status())
            self._next_try = time.monotonic()
        if time.monotonic() < self._next_try:
            return
        self._failures += 1
        if link.reconnect():
            self.get_logger().info("[%s] Create 2 port %r back after %d attempt(s); stream resumed", self.component_name, self.port, self._failures)
            self._failures = 0
            self.odometry.reset_reference()  # the counters may have restarted: keep the pose, re-reference
            self.stopped = False
            self._stop("reconnected")  # a robot that kept the old command while we were away stops
            self.health_status.set_healthy()
            return
        self.health_status.set_fail_system(message=link.lost or f"Create 2 port {self.port!r} lost")
        self._next_try = time.monotonic() + self.reconnect_policy.delay(self._failures)


# Create2PortError is part of this module's interface: activation raises it.
__all__ += ["Create2PortError"]
