"""``Create2Base``: an iRobot Create 2 as a robot plugin (``/cmd_vel`` in; odometry, bumps and
battery out), with the safety that belongs at the driver.

Built on :class:`emos.actors.hardware.plugin.RobotPlugin`: one serial transport (115200 baud),
the OI handshake on every (re)open (Start, Safe, the sensor stream), a decoder (the checked
stream frames of ``protocol.StreamParser`` -> odometry from the encoder counts on ``odom``,
either bumper on ``bumper``, ``BatteryState`` on ``battery``) and an encoder (``command``: Twist
-> Drive Direct, ``v +- w * 0.235 / 2`` mm/s, right first). Keys are the Simulator's where they
mean the same (``command``, ``odom``), so a recipe swaps one for the other.

* Watchdog: no fresh command for ``cmd_timeout`` s of robot time -> one Drive Direct (0, 0),
  because the Create 2 keeps its last command forever (OI spec, Drive Direct has no timeout).
* Bump stop: while a bumper is pressed, commands that drive forward or turn are replaced by a
  stop; pure reverse (both wheels <= 0) is let through so the robot can back off the obstacle.
* Port missing/taken: activation fails with the port named. Lost mid-run: SYSTEM_FAILURE naming
  the port, a stop is attempted, the reconnect ladder reopens it; the stream and odometry
  resume (the odometry keeps its pose, re-referenced) and the first thing sent is a stop.
* Events: ``bump`` (a bumper pressed), ``low_battery`` (below 15 %). Actions: ``stop_base``,
  ``set_oi_mode`` (safe/full/passive), ``seek_dock``.
"""
from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.core import clock
from emos.geometry import quaternion_of_yaw
from emos.msgs.nav import Odometry
from emos.msgs.sensor import BatteryState
from emos.msgs.std import Bool

from ..plugin import Command, Feedback, PluginConfig, PluginEvent, RobotPlugin, SerialTransport, plugin_action
from . import protocol as P
from .driver import Create2PortError
from .odometry import DiffDriveOdometry

__all__ = ["Create2Base", "Create2Config", "Create2PortError", "twist_to_wheels"]

LOW_BATTERY = 0.15  # fraction of capacity below which ``low_battery`` fires
SEEK_DOCK = 143  # OI spec, "Seek Dock" (no data bytes)
PASSIVE_START = P.START  # Start puts the OI in Passive mode


def twist_to_wheels(v: float, w: float, wheel_base: float = P.WHEEL_BASE_M) -> tuple[float, float]:
    """(right, left) wheel speeds in mm/s for a body twist (m/s, rad/s)."""
    return (v + w * wheel_base / 2.0) * 1000.0, (v - w * wheel_base / 2.0) * 1000.0


@define(kw_only=True)
class Create2Config(PluginConfig):
    """``port``: the serial device (``/dev/ttyUSB0``, or an emulator's pty)."""

    loop_rate: float = field(default=1.0 / P.STREAM_PERIOD_S, validator=V.finite_positive)  # poll = the stream period
    port: str = field(default="/dev/ttyUSB0", validator=V.non_empty_str)
    baudrate: int = field(default=P.BAUD_RATE, converter=int, validator=V.int_at_least(1200))
    cmd_timeout: float = field(default=0.5, converter=float, validator=V.finite_positive)
    frame_id: str = field(default="odom", validator=V.non_empty_str)
    child_frame_id: str = field(default="base_link", validator=V.non_empty_str)


def _bumped(topic: Any) -> Any:
    return topic.msg.data == True  # noqa: E712 - builds a condition, not a Python comparison


def _low_battery(topic: Any) -> Any:
    return topic.msg.percentage < LOW_BATTERY


class Create2Base(RobotPlugin):
    """See the module docstring. ``port``/``cmd_timeout`` are shortcuts for the config's fields."""

    plugin_name = "create2"
    description = "iRobot Create 2 differential base (Open Interface over serial)"
    feedback: ClassVar[Mapping[str, Feedback]] = {
        "odom": Feedback(msg_type="Odometry", topic="/odom", help="pose and twist from the wheel encoders"),
        "bumper": Feedback(msg_type="Bool", topic="/bumper", help="either bumper pressed"),
        "battery": Feedback(msg_type="BatteryState", topic="/battery", help="voltage, current, charge, percentage"),
    }
    commands: ClassVar[Mapping[str, Command]] = {"command": Command(msg_types=("Twist",), topic="/cmd_vel", timeout="cmd_timeout",
                                   help="body twist -> Drive Direct")}
    plugin_events: ClassVar[Mapping[str, PluginEvent]] = {
        "bump": PluginEvent(feedback="bumper", condition=_bumped, when="bumper.data == True", help="a bumper was pressed"),
        "low_battery": PluginEvent(feedback="battery", condition=_low_battery, when=f"battery.percentage < {LOW_BATTERY}",
                                   help="the battery fell below 15 %"),
    }

    def __init__(self, component_name: str = "create2", config: Create2Config | None = None, *,
                 port: str | None = None, cmd_timeout: float | None = None, **kwargs: Any) -> None:
        config = config or Create2Config()
        if port is not None:
            config.port = port  # validated on set
        if cmd_timeout is not None:
            config.cmd_timeout = cmd_timeout
        super().__init__(component_name, config, **kwargs)
        self.config: Create2Config
        self.parser = P.StreamParser(expected_ids=P.DRIVER_STREAM_IDS)
        self.odometry = DiffDriveOdometry()
        self.bumped = False
        self.stopped = True  # the last thing sent (or the power-on state) is "stand still"
        self._reversing = True  # the last thing sent moves no wheel forward
        self.stops_sent = 0  # watchdog and bump stops, for tests and logs
        self.stop_log: list[tuple[float, str]] = []  # (robot time, why) of each stop sent, the last 100
        self.write_stamps: collections.deque[float] = collections.deque(maxlen=4096)  # perf_counter after each Drive Direct write
        self._last_frame: P.SensorFrame | None = None
        self._last_frame_time: float | None = None

    @classmethod
    def config_class(cls) -> type[Create2Config]:
        return Create2Config

    @property
    def port(self) -> str:
        return self.config.port

    @classmethod
    def robot_config(cls) -> Any:
        from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType

        top = P.MAX_WHEEL_SPEED_MM_S / 1000.0
        return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                           geometry_params=np.array([0.17, 0.09]),  # radius, height (m): the Create 2's body
                           ctrl_vx_limits=LinearCtrlLimits(max_vel=top, max_acc=1.0, max_decel=1.5),
                           ctrl_omega_limits=AngularCtrlLimits(max_vel=2 * top / P.WHEEL_BASE_M, max_acc=3.0,
                                                               max_decel=3.0, max_steer=math.pi / 3),  # unused by a diff drive; must be valid
                           wheel_base=P.WHEEL_BASE_M)

    # -- transport and handshake ---------------------------------------------------------------------
    def make_transports(self) -> Mapping[str, SerialTransport]:
        return {"serial": SerialTransport("Create 2", self.config.port, self.config.baudrate)}

    def on_open(self, name: str, transport: Any) -> None:
        # OI spec, Getting Started: Start first; Safe so Drive Direct is obeyed with the robot's
        # own cliff and wheel-drop protection; then the sensor stream every 15 ms.
        transport.write(bytes([P.START, P.SAFE]) + P.stream_request(P.DRIVER_STREAM_IDS))

    def on_close(self) -> None:
        transport = self.transports.get("serial")
        if isinstance(transport, SerialTransport) and transport.lost is None:
            try:  # the Create 2 keeps its last command forever: leave it standing still
                transport.write(P.drive_direct(0, 0) + P.pause_resume(False))
                transport.flush()
            except Exception:  # noqa: BLE001 - best effort on the way out
                pass

    # -- commands ------------------------------------------------------------------------------------
    def on_command(self, key: str, msg: Any) -> None:
        right, left = twist_to_wheels(float(msg.linear.x), float(msg.angular.z))
        if not (math.isfinite(right) and math.isfinite(left)):
            self._rlog.warning("nan", "[%s] %s: non-finite twist refused", self.component_name, key)
            return
        if self.bumped and not (right <= 0.0 and left <= 0.0):
            self._stop("bumper pressed")
            return
        if self._drive(right, left):
            self.stopped = P.clamp_speed(right) == 0 and P.clamp_speed(left) == 0
            self._reversing = right <= 0.0 and left <= 0.0

    def on_command_timeout(self, key: str) -> None:
        topic = self.get_in_topic(key)
        self._stop(f"no {topic.name if topic is not None else key} for {self.config.cmd_timeout:g} s (watchdog)")

    def _drive(self, right: float, left: float) -> bool:
        stamp = self.send("serial", P.drive_direct(right, left))
        if stamp is not None:
            self.write_stamps.append(stamp)
        return stamp is not None

    def _stop(self, why: str) -> None:
        if self.stopped or not self.transports:
            return
        if self._drive(0, 0):
            self.stopped, self._reversing = True, True
            self.stops_sent += 1
            self.stop_log = [*self.stop_log[-99:], (clock.now(), why)]
            self._rlog.warning(("stop", why), "[%s] %s: stopping the base on %s", self.component_name, why, self.port)

    # -- feedback ------------------------------------------------------------------------------------
    def on_data(self, name: str, data: bytes) -> None:
        now = clock.now()
        for frame in self.parser.feed(data):
            dt = now - self._last_frame_time if self._last_frame_time is not None else 0.0
            self.odometry.update(frame.get(P.PKT_ENCODER_LEFT), frame.get(P.PKT_ENCODER_RIGHT), dt if dt > 0 else P.STREAM_PERIOD_S)
            self._last_frame, self._last_frame_time = frame, now
            if frame.bumped and not self.bumped:
                self.bumped = True
                self.stopped = False  # whatever it was doing, send the stop now
            elif not frame.bumped:
                self.bumped = False

    def on_poll(self) -> None:
        if self.bumped and not self._reversing:  # backing off the obstacle is what we want
            self._stop("bumper pressed")
        if self._last_frame is not None:
            self._publish(self._last_frame)

    def _publish(self, frame: P.SensorFrame) -> None:
        odo = self.odometry
        msg = Odometry()
        msg.header.stamp = clock.stamp()
        msg.header.frame_id = self.config.frame_id
        msg.child_frame_id = self.config.child_frame_id
        msg.pose.pose.position.x, msg.pose.pose.position.y = odo.x, odo.y
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = quaternion_of_yaw(odo.th)
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = odo.v, odo.w
        self.emit("odom", msg)
        self.emit("bumper", Bool(data=frame.bumped))
        self.emit("battery", battery_state(frame, msg.header.stamp))

    # -- link ----------------------------------------------------------------------------------------
    def on_lost(self, name: str, transport: Any) -> None:
        if transport.force_write(P.drive_direct(0, 0)):  # still reachable (a read error, not a dead port)
            self.stopped = True

    def on_reconnected(self, name: str, transport: Any) -> None:
        self.odometry.reset_reference()  # the counters may have restarted: keep the pose, re-reference
        self.stopped = False
        self._stop("reconnected")  # a robot that kept the old command while we were away stops

    # -- plugin actions ------------------------------------------------------------------------------
    @plugin_action("send Drive Direct (0, 0) now")
    def stop_base(self) -> bool:
        self.stopped = False
        self._stop("stop_base action")
        return self.stopped

    @plugin_action("switch the OI mode: 'safe' (cliff/wheel-drop protection), 'full' (none) or 'passive'")
    def set_oi_mode(self, mode: str) -> bool:
        opcodes = {"safe": P.SAFE, "full": P.FULL, "passive": PASSIVE_START}
        if mode not in opcodes:
            raise ValueError(f"[{self.component_name}] set_oi_mode: mode must be one of {sorted(opcodes)}, got {mode!r}")
        return self.send("serial", bytes([opcodes[mode]])) is not None

    @plugin_action("drive to the Home Base and dock (OI Seek Dock)")
    def seek_dock(self) -> bool:
        return self.send("serial", bytes([SEEK_DOCK])) is not None


def battery_state(frame: P.SensorFrame, stamp: Any = None) -> BatteryState:
    """A BatteryState from a stream frame (OI packets 21-26: mV, mA, mAh)."""
    capacity = frame.get(P.PKT_CAPACITY)
    charging = frame.get(P.PKT_CHARGING_STATE)  # OI: 0 not charging, 1-3 charging, 4 waiting, 5 fault
    status = (BatteryState.POWER_SUPPLY_STATUS_DISCHARGING if charging == 0 else
              BatteryState.POWER_SUPPLY_STATUS_CHARGING if charging in (1, 2, 3) else
              BatteryState.POWER_SUPPLY_STATUS_NOT_CHARGING if charging == 4 else BatteryState.POWER_SUPPLY_STATUS_UNKNOWN)
    msg = BatteryState(voltage=frame.get(P.PKT_VOLTAGE) / 1000.0, current=frame.get(P.PKT_CURRENT) / 1000.0,
                       charge=frame.get(P.PKT_CHARGE) / 1000.0, capacity=capacity / 1000.0,
                       design_capacity=capacity / 1000.0,
                       percentage=frame.get(P.PKT_CHARGE) / capacity if capacity else math.nan,
                       power_supply_status=status, power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LION,
                       present=bool(capacity))
    if stamp is not None:
        msg.header.stamp = stamp
    return msg
