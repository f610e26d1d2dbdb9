"""``DriveManager``: the last gate before the motors.

Every command from the controller goes through the safety zones (emergency stop, slowdown),
the velocity/acceleration limits and the optional smoothing of :class:`DriveSafety`, and then
the swept-footprint check (``swept_check``): the robot's footprint over the command's period
and the stop after it, rotations included, against the latest scan and the blind-spot memory;
a command that would touch is slowed along its path or becomes a stop (docs/safety.md). With
``mover_prediction_time`` the check also takes the predicted path of tracked moving obstacles
(``controllers.movers.MoverWatch``) as occupied (docs/missions.md, "Giving way to people"). A
watchdog at ``loop_rate`` stops the robot (zero command, SYSTEM failure naming the topic) when
the command input goes stale or its publisher process died, when odometry goes stale
(``closed_loop``), or when the scan goes stale: the robot never drives on old information.
Right after activation an input that has not sent its first message yet holds the robot without
a failure until its timeout has passed (a restart must not fail on its own start-up).
The unblock maneuvers (``move_forward``, ``move_backward``, ``rotate_in_place``,
``move_to_unblock``) are methods (for event actions) and Trigger services.

Several sources may drive the robot (the Controller, a recovery behavior, the docking server, a
teleop): ``command_inputs`` gives each its own topic on the ``command`` key with a priority and a
timeout, as ROS 2's twist_mux does. The highest-priority input with a command younger than its
timeout drives; a lower one is ignored while a higher one is live; an input silent past its
timeout releases the robot to the next. Whichever wins goes through the same safety pipeline,
and through the speed cap of ``speed_mask`` (the zones the Controller obeys, enforced here too).
"""
from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.errors import ConfigError
from emos.io.topic import Topic, normalize_topic_name
from emos.msgs.geometry import Twist, TwistStamped
from emos.msgs.nav import Odometry
from emos.msgs.sensor import LaserScan
from emos.msgs.srv import TriggerRequest, TriggerResponse
from emos.msgs.std import Bool, Header

from ..controllers.movers import MoverWatch, WallFilter, static_map_path
from ..controllers.sensors import obstacle_points
from ..costmap.config import mask_path
from ..costmap.filters import KeepoutObstacles, SpeedFilter, load_filter_mask
from ..safety import CommandFilterConfig, DriveSafety, SafetyZonesConfig, SweptConfig
from ..safety import maneuvers as M
from ..safety.blind_spot import BlindSpotConfig, BlindSpotMemory
from ..safety.zones import ZoneCheck
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, pose_of, scan_of, twist_msg, twist_of, velocity_of

__all__ = ["CommandInput", "DriveManager", "DriveManagerConfig"]

KEEPOUT_REACH = 2.0  # m round the robot: beyond any stop the swept check plans (2 m/s, latency, braking)
SETTLE_S = 1.0  # node-clock s: the longest a maneuver waits for the base to come to rest before it is re-planned
MOVER_KEEP_CLEAR = 0.1  # m beyond the footprint where a tracked mover's predicted trail ends (mover_prediction_time)


def _seconds(lo: float = 1e-3, hi: float = 1e3) -> Any:
    return in_range(min_value=lo, max_value=hi)


def _pose(value: Any) -> tuple[float, float, float]:
    try:
        x, y, yaw = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"DriveManagerConfig.sensor_pose: expected (x, y, yaw), got {value!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise ValueError(f"DriveManagerConfig.sensor_pose: expected finite (x, y, yaw), got {value!r}")
    return (x, y, yaw)


@define(frozen=True)
class CommandInput:
    """One prioritised command input (an entry of twist_mux's ``topics``): ``topic`` (its name),
    ``priority`` (higher wins), ``timeout`` (s on the node's clock: a command older than this no
    longer holds the robot, and the next input drives), ``msg_type`` (``Twist`` or ``TwistStamped``)."""

    topic: str
    priority: int
    timeout: float
    msg_type: str = "Twist"


def _command_inputs(value: Any) -> tuple[CommandInput, ...]:
    """``command_inputs`` from CommandInput or dicts of its fields, each field checked with the
    entry named: a bad one is refused where the config is made."""
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__iter__"):
        raise TypeError(f"DriveManagerConfig.command_inputs: expected a list of CommandInput (topic, priority, timeout), "
                        f"got {type(value).__name__}")
    out: list[CommandInput] = []
    for i, item in enumerate(value):
        where = f"DriveManagerConfig.command_inputs[{i}]"
        if isinstance(item, Mapping):
            unknown = set(item) - {"topic", "priority", "timeout", "msg_type"}
            if unknown or not {"topic", "priority", "timeout"} <= set(item):
                raise ValueError(f"{where}: expected the keys topic, priority, timeout (and msg_type), got {sorted(item)}")
            item = CommandInput(**item)
        if not isinstance(item, CommandInput):
            raise TypeError(f"{where}: expected a CommandInput or a dict of its fields, got {type(item).__name__}")
        try:
            topic = normalize_topic_name(item.topic)
        except ValueError as exc:
            raise ValueError(f"{where}.topic: {exc}") from None
        if isinstance(item.priority, bool) or not isinstance(item.priority, int):
            raise ValueError(f"{where}.priority: expected an integer, got {item.priority!r}")
        if isinstance(item.timeout, bool) or not isinstance(item.timeout, (int, float)) or not (math.isfinite(item.timeout) and item.timeout > 0):
            raise ValueError(f"{where}.timeout: expected a number of seconds > 0, got {item.timeout!r}")
        if item.msg_type not in ("Twist", "TwistStamped"):
            raise ValueError(f"{where}.msg_type: expected 'Twist' or 'TwistStamped', got {item.msg_type!r}")
        for j, other in enumerate(out):
            if other.topic == topic:
                raise ValueError(f"{where}.topic: {item.topic!r} is already command_inputs[{j}]'s topic: one entry per topic")
            if other.priority == item.priority:
                raise ValueError(f"{where}.priority: {item.priority} is already the priority of command_inputs[{j}] "
                                 f"({other.topic}): two inputs of one priority would interleave their commands")
        out.append(CommandInput(topic=topic, priority=int(item.priority), timeout=float(item.timeout),
                                msg_type=item.msg_type))
    return tuple(out)


@define(kw_only=True)
class DriveManagerConfig(NavComponentConfig):
    """Zones in metres beyond the footprint (``critical_zone_angle``: full cone, degrees).
    ``closed_loop``: also require fresh odometry to drive. ``cmd_timeout``, ``odom_timeout``,
    ``sensor_timeout`` (s): older inputs stop the robot. ``smooth_commands``: low-pass filter
    (``smoothing_time_constant`` s) on top of the acceleration limits. ``max_distance`` (m) and
    ``max_rotation`` (rad): default size of the unblock maneuvers. ``stop_hold_time`` (s): how
    long ``stop()`` (an event action) holds the robot still whatever the controller sends.
    ``command_inputs``: prioritised command inputs (twist_mux; empty: the one ``command`` input,
    timed out after ``cmd_timeout``). ``speed_mask``: a speed filter mask (the Controller's): every
    command sent is capped to the zone's limit at the robot's location. ``keepout_mask``: a keepout
    filter mask (the Controller's, in the frame of ``location``): the swept check takes the edges of
    its zones as obstacles, so no input (a recovery behavior, docking, a teleop) drives the robot
    into a zone."""

    loop_rate: float = rate_field(20.0)
    closed_loop: bool = field(default=True)
    critical_zone_distance: float = field(default=0.1, validator=in_range(min_value=0.0, max_value=100.0))
    critical_zone_angle: float = field(default=90.0, validator=in_range(min_value=0.0, max_value=360.0))
    slowdown_zone_distance: float = field(default=0.3, validator=in_range(min_value=0.0, max_value=100.0))
    smooth_commands: bool = field(default=False)
    smoothing_time_constant: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=100.0))
    cmd_timeout: float = field(default=0.3, validator=_seconds())
    odom_timeout: float = field(default=0.5, validator=_seconds())
    sensor_timeout: float = field(default=0.5, validator=_seconds())
    max_distance: float = field(default=0.3, validator=in_range(min_value=0.0, max_value=100.0))
    max_rotation: float = field(default=math.pi / 2, validator=in_range(min_value=0.0, max_value=2 * math.pi))
    safety_margin: float = field(default=0.05, validator=in_range(min_value=0.0, max_value=10.0))
    stop_hold_time: float = field(default=1.0, validator=in_range(min_value=0.0, max_value=3600.0))
    blind_spot_memory_time: float = field(default=10.0, validator=in_range(min_value=0.0, max_value=600.0))
    """s: obstacle points seen this long ago still block backing up where the laser cannot see
    now (behind a 270 degree laser); 0 turns the memory off. Needs the ``location`` input."""
    blind_spot_radius: float = field(default=2.0, validator=in_range(min_value=0.1, max_value=50.0))
    sensor_pose: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), converter=_pose)
    """(x, y, yaw) of the laser on the robot (m, rad): where its points are, for the swept check
    and the blind-spot memory (the Jackal's is (0.055, 0, 0))."""
    swept_check: bool = field(default=True)
    """Check every command's swept footprint (then its stop) against the scan and the blind-spot
    memory; the motion model below is the realistic Jackal's (docs/safety.md)."""
    swept_margin: float = field(default=0.02, validator=in_range(min_value=0.0, max_value=1.0))
    """m: the clearance the swept footprint keeps from every obstacle point."""
    actuation_latency: float = field(default=0.15, validator=in_range(min_value=0.0, max_value=2.0))
    """s: from a command leaving here to the wheels acting on it (transport, compute charged, the
    motor response), beyond the scan's age."""
    max_braking: float = field(default=4.9, validator=in_range(min_value=0.01, max_value=1000.0))
    """m/s^2: the body's braking limit (friction: mu g); the robot's max_decel is used if lower."""
    yaw_lag: float = field(default=0.4, validator=in_range(min_value=0.0, max_value=5.0))
    """s: the body's yaw rate lag behind its wheels (it keeps turning yaw_rate * yaw_lag after a stop)."""
    yaw_gain_min: float = field(default=0.6, validator=in_range(min_value=0.05, max_value=1.0))
    """The least fraction of the commanded yaw rate the body turns at (skid-steer slip)."""
    command_inputs: tuple[CommandInput, ...] = field(factory=tuple, converter=_command_inputs)
    """Prioritised command inputs, each its own topic on the ``command`` key (see the module doc).
    Empty (the default): the ``command`` key's one topic, priority 0, timeout ``cmd_timeout``."""
    mover_prediction_time: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=5.0))
    """s: scan clusters tracked as moving (``controllers.movers.MoverWatch``) count, for the swept
    check, as obstacles over the whole path they are predicted to walk in this time, so the robot
    does not drive into where a person will be by the time it has stopped (0: off, the scan is
    taken as static)."""
    static_map: str = field(default="", validator=static_map_path)
    """A map_server YAML in the frame of the ``location`` input ('': none): with
    ``mover_prediction_time``, a tracked "mover" within ``static_map_clearance`` m of the map's
    walls is a piece of wall the robot's own motion smeared and gets no predicted trail
    (``controllers.movers.WallFilter``; the scan's points themselves are always checked)."""
    static_map_clearance: float = field(default=0.1, validator=in_range(min_value=0.0, max_value=1.0))
    speed_mask: str = field(default="", validator=mask_path("speed"))
    """A speed filter mask (Nav2's speed filter; ``emos map zones``): inside its zones every
    command leaving here is scaled down to the zone's limit, whichever input sent it."""
    keepout_mask: str = field(default="", validator=mask_path("keepout"))
    """A keepout filter mask (Nav2's keepout filter; ``emos map zones``): the edges of its zones
    near the robot are obstacles to the swept check (needs ``swept_check`` and the ``location``
    input), whichever input sent the command. A robot already inside a zone may drive out."""

    def __attrs_post_init__(self) -> None:
        if self.keepout_mask and not self.swept_check:
            # The swept check is what keeps the zones: a mask without it would be ignored silently.
            raise ValueError(f"DriveManagerConfig: keepout_mask {self.keepout_mask!r} is kept by the swept check; "
                             f"set swept_check=True (or leave keepout_mask empty)")
        if self.slowdown_zone_distance < self.critical_zone_distance:
            raise ValueError(f"DriveManagerConfig: slowdown_zone_distance ({self.slowdown_zone_distance}) must be >= "
                             f"critical_zone_distance ({self.critical_zone_distance})")


class DriveManager(NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/control", msg_type="Twist"), number=-1),
        "multi_command": AllowedTopic(types=("TwistArray",), default=Topic(name="/control_list", msg_type="TwistArray")),
        "sensor_data": AllowedTopic(types=("LaserScan", "Float64", "Float32"), default=Topic(name="/scan", msg_type="LaserScan"), number=11),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry")),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "robot_command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/cmd_vel", msg_type="Twist"), required=True),
        "emergency_stop": AllowedTopic(types=("Bool",), default=Topic(name="/emergency_stop", msg_type="Bool")),
    }
    config: DriveManagerConfig

    def __init__(self, component_name: str, config: DriveManagerConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        if self.config.command_inputs:  # each prioritised input is a topic of the command key
            self.inputs(command=[Topic(name=c.topic, msg_type=c.msg_type) for c in self.config.command_inputs])
        # Event run type by default: commands are passed on as they arrive (no added latency);
        # the watchdog timer runs beside at loop_rate. Timed also works (commands wait for a tick).
        self._default_trigger = "trigger" not in kwargs and "run_type" not in kwargs
        if self._default_trigger:
            self.trigger = self._command_topics()

    def _command_topics(self) -> list[Topic]:
        return [*self.get_in_topics("command"), *self.get_in_topics("multi_command")]

    def _mux_table(self) -> list[tuple[int, float, str, Topic]]:
        """(priority, timeout s, key, topic) of every command input. Without ``command_inputs``:
        the command topic and ``multi_command`` at priority 0, timeout ``cmd_timeout`` (the newest
        of the two drives, as before). With them: each entry's topic, which must be wired on the
        ``command`` key (and nothing else be); ``multi_command`` ranks with the lowest entry."""
        cfg = self.config
        wired = self.get_in_topics("command")
        multi = [("multi_command", t) for t in self.get_in_topics("multi_command")]
        if not cfg.command_inputs:
            if len(wired) > 1:
                raise ConfigError(f"DriveManager {self.component_name!r}: {len(wired)} topics on the command input "
                                  f"({', '.join(t.name for t in wired)}) and no command_inputs to rank them: their commands "
                                  "would interleave; give DriveManagerConfig(command_inputs=[CommandInput(topic, priority, timeout), ...])")
            return [(0, cfg.cmd_timeout, key, t) for key, t in [("command", t) for t in wired] + multi]
        by_name = {t.name: t for t in wired}
        missing = [c.topic for c in cfg.command_inputs if c.topic not in by_name]
        extra = sorted(set(by_name) - {c.topic for c in cfg.command_inputs})
        if missing or extra:
            raise ConfigError(f"DriveManager {self.component_name!r}: the command input's topics ({', '.join(by_name) or 'none'}) "
                              f"do not match command_inputs" + (f": {', '.join(missing)} not wired" if missing else "")
                              + (f": {', '.join(extra)} has no command_inputs entry" if extra else "")
                              + " (a later driver.inputs(command=...) replaced them?)")
        low = min(c.priority for c in cfg.command_inputs)
        table = [(c.priority, c.timeout, "command", by_name[c.topic]) for c in cfg.command_inputs]
        return table + [(low, cfg.cmd_timeout, key, t) for key, t in multi]

    @classmethod
    def config_class(cls) -> type[DriveManagerConfig]:
        return DriveManagerConfig

    # -- lifecycle -----------------------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        cfg = self.config
        zones = SafetyZonesConfig(critical_zone_distance=cfg.critical_zone_distance, critical_zone_angle=cfg.critical_zone_angle,
                                  slowdown_zone_distance=cfg.slowdown_zone_distance)
        filt = CommandFilterConfig(control_time_step=1.0 / cfg.loop_rate, smooth_commands=cfg.smooth_commands,
                                   smoothing_time_constant=cfg.smoothing_time_constant)
        swept = SweptConfig(margin=cfg.swept_margin, latency=cfg.actuation_latency, hold=1.0 / cfg.loop_rate,
                            max_braking=cfg.max_braking, yaw_lag=cfg.yaw_lag, yaw_gain_min=cfg.yaw_gain_min) if cfg.swept_check else None
        self._safety = DriveSafety(cfg.robot, zones, filt, swept=swept)
        self._scan_stamp: float | None = None  # node-clock time of the scan behind the obstacles
        self._scan_age = 0.0  # s since that scan arrived
        self._sent: deque[tuple[float, np.ndarray]] = deque()  # (node time, command) sent recently, for the swept check
        self._command = np.zeros(3)
        self._stopped_reason = ""
        self._estop: bool | None = None
        self._maneuver: tuple[M.Maneuver, int] | None = None
        self._held_until = -math.inf
        self._mux = self._mux_table()
        if self._default_trigger and self.run_type.value == "Event":
            self._trigger = self._command_topics()  # the topics wired now (inputs may have changed since __init__)
        self._driving: str | None = None  # the command input that drives now (its topic name), for the log
        self._speed_filter = SpeedFilter(load_filter_mask(cfg.speed_mask, "speed")) if cfg.speed_mask else None
        self._keepout = KeepoutObstacles(load_filter_mask(cfg.keepout_mask, "keepout")) if cfg.keepout_mask else None
        self._keepout_edges = np.zeros((0, 2))  # the keepout edges of the swept check's points (robot frame)
        self._keepout_pose: np.ndarray | None = None  # the pose they were placed at
        self._cmd_seen: dict[str, Any] = {}  # per command topic: the message whose writers were noted
        self._cmd_writers: dict[str, list[int]] = {}
        # The swept check's moving obstacles (none on the static map's walls)
        self._mover_watch = (MoverWatch(walls=WallFilter.from_map_file(cfg.static_map, cfg.static_map_clearance))
                             if cfg.mover_prediction_time > 0 else None)
        self._blind_spot = (BlindSpotMemory(BlindSpotConfig(memory_time=cfg.blind_spot_memory_time, radius=cfg.blind_spot_radius))
                            if cfg.blind_spot_memory_time > 0 else None)
        self._remembered_scan: Any = None  # the scan message last put into the blind-spot memory
        self._last_out = np.zeros(3)  # the last command sent to the base
        self._settling: tuple[Any, float] | None = None  # (maneuver builder, node time of the stop)
        for name in ("move_forward", "move_backward", "rotate_in_place", "move_to_unblock"):
            self.create_service(f"{self.component_name}/{name}", TriggerRequest, TriggerResponse, self._trigger_service(name))

    def custom_on_activate(self) -> None:
        self._activated_at = clock.now()  # the node's clock (simulated seconds under a simulator), as every age here
        if self.run_type.value == "Event":
            self.create_timer(1.0 / self.config.loop_rate, self._watchdog)

    def _trigger_service(self, name: str) -> Any:
        def serve(request: TriggerRequest) -> TriggerResponse:
            ok, message = getattr(self, f"_{name}")()
            return TriggerResponse(success=ok, message=message)

        return serve

    # -- the command path ------------------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        # Event: a command arrived. Timed: the main timer (which also plays maneuvers).
        if msg is None:
            self._watchdog()
        elif self._maneuver is None and not self._outranked(topic):
            self._drive()

    def _outranked(self, topic: Any) -> bool:
        """A command arrived on an input that does not drive now (a higher one is live): it is
        ignored, as twist_mux ignores it; the watchdog keeps passing on the one that drives."""
        if len(self._mux) < 2 or topic is None:
            return False
        selected = self._selected_input()
        return selected is not None and selected[1].name != getattr(topic, "name", topic)

    def _watchdog(self) -> None:
        if self._maneuver is not None:
            self._play_maneuver()
            return
        self._drive()

    def _selected_input(self) -> tuple[str, Topic, float, float] | None:
        """(key, topic, age s, timeout s) of the input that drives now: the highest-priority one
        with a command younger than its timeout (the newest among equals). When none is live:
        the newest command of any input (stale: the caller stands or stops on it). None when no
        command has arrived at all."""
        live: tuple[int, float, tuple[str, Topic, float, float]] | None = None
        newest: tuple[str, Topic, float, float] | None = None
        for priority, timeout, key, topic in self._mux:
            age = self.input_age(topic)
            if age is None:
                continue
            if newest is None or age < newest[2]:
                newest = (key, topic, age, timeout)
            if age <= timeout and (live is None or (priority, -age) > (live[0], -live[1])):
                live = (priority, age, (key, topic, age, timeout))
        return live[2] if live is not None else newest

    def _latest_command(self) -> tuple[np.ndarray, float, str, Topic, float] | None:
        """(command, age s, key, topic, timeout s) of the input that drives (``_selected_input``); None if none."""
        selected = self._selected_input()
        if selected is None:
            return None
        key, topic, age, timeout = selected
        msg = self.get_input(topic)
        assert msg is not None  # the input has an age, so a message has arrived
        if topic.name != self._driving:
            if self._driving is not None and len(self._mux) > 1:  # a recovery, docking, a teleop: worth a line
                # Rate-limited per pair: a controller that publishes on two inputs of one priority
                # (ctrl_publish_type "Parallel") hands over between them at every other command.
                self._report.log(logging.INFO, f"driving:{topic.name}<{self._driving}", "[%s] command input %s drives (was %s)",
                                 self.component_name, topic.name, self._driving, logger=self.get_logger())
            self._driving = topic.name
        if key == "multi_command":
            if len(msg.linear_velocities) == 0:
                raise BadInput("multi_command: empty TwistArray")
            cmd = np.array([msg.linear_velocities[0, 0], msg.linear_velocities[0, 1], msg.angular_velocities[0, 2]])
            if not np.all(np.isfinite(cmd)):
                raise BadInput(f"multi_command: NaN/inf velocity {cmd.tolist()}")
        else:
            cmd = twist_of(msg)
        return cmd, age, key, topic, timeout

    def _blocking_reason(self) -> tuple[str | Topic, str] | None:
        """(input key or command topic, reason) when the robot must not drive now, else None;
        sets the command."""
        cfg = self.config
        try:
            latest = self._latest_command()
        except BadInput as exc:
            return "command", str(exc)
        if latest is None:
            return None  # nothing asked of the robot yet: it stands still, and that is no failure
        cmd, age, key, topic, timeout = latest
        src = self.get_input(topic)
        self._command_stamp = src.header.stamp if isinstance(src, TwistStamped) else None
        if age > timeout and not np.any(cmd):
            # The last word was "stand still" (a controller or a motion test that finished): the
            # robot keeps standing still, and a source that said so and went quiet is no fault.
            self._command = np.zeros(3)
            return None
        # A dead publisher first: its last command is soon too old as well, and "it died" says
        # more than "no command" (which of the two a loaded machine noticed first was chance).
        if not self._publisher_alive(topic, src):
            return topic, f"the process that published the last command on {topic.name} died"
        if age > timeout:
            what = "cmd_timeout" if not cfg.command_inputs or key == "multi_command" else f"{topic.name} timeout"
            return topic, f"no command for {age:.2f} s ({what} {timeout:g} s)"
        self._command = self._speed_capped(cmd)
        if cfg.closed_loop:
            odom_age = self.age_of("location")
            if odom_age is None or odom_age > cfg.odom_timeout:
                what = "no odometry yet" if odom_age is None else f"odometry is {odom_age:.2f} s old (odom_timeout {cfg.odom_timeout:g} s)"
                return "location", what
        return None

    def _awaiting_first_inputs(self) -> bool:
        """Just activated, and odometry or a scan has not sent its first message yet. The robot
        is held, but that is no SYSTEM failure until the input's timeout has passed since
        activation: a (re)started DriveManager whose first command comes before its first scan
        would otherwise fail at once, and an ``on_system_fail`` restart would loop on it."""
        cfg = self.config
        if clock.now() - getattr(self, "_activated_at", -math.inf) > max(cfg.odom_timeout, cfg.sensor_timeout):
            return False
        ages = [self.age_of("location")] if cfg.closed_loop else []
        ages += [self.input_age(t) for t in self.get_in_topics("sensor_data") if t.msg_type is LaserScan]
        return any(age is None for age in ages)

    def _publisher_alive(self, topic: Topic, msg: Any) -> bool:
        """Is the process that sent the current command (on ``topic``) still running? A restarted
        publisher (same ring, new pid) does not revive a command its dead predecessor sent."""
        from emos.core.node import process_alive

        # A newer message (each arrival is decoded into a new object; its age cannot tell: on
        # simulated time it does not grow while the simulator waits): note who can have sent it.
        if msg is not self._cmd_seen.get(topic.name):
            self._cmd_writers[topic.name] = [pid for pid in self.node.publisher_pids(topic) if pid <= 0 or process_alive(pid)]
            self._cmd_seen[topic.name] = msg
        writers = self._cmd_writers.get(topic.name)
        return not writers or any(pid <= 0 or process_alive(pid) for pid in writers)

    def _speed_capped(self, cmd: np.ndarray) -> np.ndarray:
        """``cmd`` within the ``speed_mask`` zone's limit at the robot's location (the Controller's
        cap, enforced here too, whichever input sent the command); unchanged outside the zones or
        without a fresh pose."""
        if self._speed_filter is None:
            return cmd
        pose = self._pose()
        if pose is None:
            return cmd
        capped: np.ndarray = self._speed_filter.capped(cmd[None, :], pose[:2], self.config.robot.ctrl_vx_limits.max_vel)[0]
        return capped

    def _fail_source(self, source: str | Topic, message: str) -> None:
        """``fail_input`` for an input key, or for one command input named by its topic."""
        if isinstance(source, Topic):
            self.health_status.set_fail_system(topic_names=[source.name], message=message)
            self._report.warning(f"input:{source.name}", "[%s] %s", self.component_name, message, logger=self.get_logger())
        else:
            self.fail_input(source, message)

    def _obstacles(self) -> tuple[Any, str]:
        """The latest scan (and any range sensors) as obstacles; None with a reason when stale."""
        scan_msg, reason = None, ""
        for topic in self.get_in_topics("sensor_data"):
            if topic.msg_type is LaserScan:
                age = self.input_age(topic)
                if age is None or age > self.config.sensor_timeout:
                    return None, f"{topic.name}: " + ("no scan yet" if age is None else f"scan is {age:.2f} s old")
                scan_msg = self.get_input(topic)
                self._scan_age = age
        if scan_msg is None:
            return None, "no LaserScan among the sensor_data inputs"
        try:
            scan = scan_of(scan_msg)
        except BadInput as exc:
            return None, str(exc)
        self._scan_stamp = scan_msg.header.stamp.to_sec() if scan_msg.header.stamp is not None else None
        self._scan_msg = scan_msg  # the swept check prepares its points once per scan message
        self._remember(scan_msg, scan)
        return scan, reason

    def _remember(self, scan_msg: Any, scan: Any) -> None:
        """Put a new scan into the blind-spot memory, at the pose odometry gives for now."""
        if self._blind_spot is None or scan_msg is self._remembered_scan:
            return
        pose = self._pose()
        if pose is not None:
            # On the node's clock: with use_sim_time the memory lasts blind_spot_memory_time
            # simulated seconds, not the few a loaded machine lets the simulator run in 10 wall s.
            self._blind_spot.update(pose, scan, clock.now(), self.config.sensor_pose)
            self._remembered_scan = scan_msg

    def _pose(self) -> np.ndarray | None:
        msg, age = self.latest("location"), self.age_of("location")
        if msg is None or age is None or age > self.config.odom_timeout:
            return None
        try:
            return pose_of(msg)
        except BadInput:
            return None  # the watchdog reports a bad location input

    def _all_around(self, scan: Any) -> Any:
        """The scan plus remembered obstacles where it cannot see (points in the robot frame);
        the scan alone when nothing is remembered there. For motion backwards."""
        pose = self._pose() if self._blind_spot is not None else None
        blind = self._blind_spot.blind_points(pose, scan) if self._blind_spot is not None and pose is not None else ()
        return np.vstack([scan.points(), blind]) if len(blind) else scan

    def _swept_inputs(self, scan: Any) -> tuple[Any, float, Any]:
        """(points in the robot frame: the scan's and the blind-spot memory's, prepared for the
        check; the scan's age s; the commands sent since (send times relative to now, commands))
        for the swept-footprint check; points None when it is off."""
        if self._safety.swept is None:
            return None, 0.0, None
        cfg = self.config
        pose = self._pose() if self._blind_spot is not None else None

        def scan_points() -> np.ndarray:
            # Once per scan (again if the pose became known since): the blind-spot memory placed
            # at the pose of the scan's arrival, as the memory placed the scan itself.
            points = obstacle_points(scan, cfg.sensor_pose)
            if self._mover_watch is not None:  # where tracked movers will walk counts as an obstacle now
                odom = self.latest("location")
                points = self._mover_watch.extend(
                    points, self._pose(), self._scan_stamp if self._scan_stamp is not None else clock.now(), cfg.mover_prediction_time,
                    float(scan.angle_increment or 0.0), pose_stamp=odom.header.stamp.to_sec() if isinstance(odom, Odometry) and odom.header.stamp is not None else None,
                    twist=velocity_of(odom), keep_clear=cfg.robot.radius + MOVER_KEEP_CLEAR)
            if self._blind_spot is not None and pose is not None:
                blind = self._blind_spot.blind_points(pose, scan, cfg.sensor_pose)
                if len(blind):
                    points = np.vstack([points, blind])
            edges = self._keepout_near()
            return np.vstack([points, edges]) if len(edges) else points

        known = pose is not None or (self._keepout is not None and self._pose() is not None)
        points = self._safety.swept_points(getattr(self, "_scan_msg", None), known, scan_points)
        now = clock.now()
        # The scan's age from its stamp (the sensor's time); a stamp from another clock (or none):
        # since it arrived here, the rest being counted in actuation_latency.
        lead = now - self._scan_stamp if self._scan_stamp is not None else math.inf
        if not 0.0 <= lead <= cfg.sensor_timeout:
            lead = min(max(self._scan_age, 0.0), cfg.sensor_timeout)
        horizon = now - lead - cfg.actuation_latency - 2.0 / cfg.loop_rate
        while len(self._sent) > 1 and self._sent[1][0] <= horizon:
            self._sent.popleft()  # keep one sent before the horizon: it still acts then
        times = np.array([t - now for t, _ in self._sent])
        return points, lead, (times, np.array([c for _, c in self._sent]).reshape(-1, 3))

    def _keepout_near(self) -> np.ndarray:
        """The keepout zones' edges within ``KEEPOUT_REACH`` of the robot (robot frame) for the
        swept check, placed at the pose odometry gives now; none without a pose or a mask."""
        self._keepout_edges, self._keepout_pose = np.zeros((0, 2)), None
        pose = self._pose() if self._keepout is not None else None
        if self._keepout is None or pose is None:
            return self._keepout_edges
        edges, inside = self._keepout.around(pose, KEEPOUT_REACH, clear=self.config.robot.radius + self.config.swept_margin)
        if inside is not None:
            self._report.warning("keepout:inside", "[%s] the robot is inside keepout zone %s: every input may drive it "
                                 "until it is out", self.component_name, inside, logger=self.get_logger())
        self._keepout_edges, self._keepout_pose = edges, pose
        return edges

    def _keepout_named(self) -> str:
        """"; keepout zone X is d m away" for a stop of the swept check with a zone's edge within
        1 m of the footprint (the points do not say which one the stop was for), else ""."""
        if not len(self._keepout_edges) or self._keepout_pose is None:
            return ""
        d = np.hypot(self._keepout_edges[:, 0], self._keepout_edges[:, 1]) - self.config.robot.radius
        i = int(np.argmin(d))
        if d[i] > KEEPOUT_REACH / 2:
            return ""
        x, y, yaw = (float(v) for v in self._keepout_pose[:3])
        px, py = self._keepout_edges[i]
        world = np.array([x + math.cos(yaw) * px - math.sin(yaw) * py, y + math.sin(yaw) * px + math.cos(yaw) * py])
        assert self._keepout is not None  # edges exist only with a mask
        return f"; keepout zone {self._keepout.zone_by(world)} is {max(d[i], 0.0):.2f} m away"

    def _range_sensors_min(self) -> float:
        """Nearest reading (m beyond the footprint) of Float range sensors, inf if none."""
        best = math.inf
        for topic in self.get_in_topics("sensor_data"):
            if topic.msg_type is not LaserScan:
                msg = self.get_input(topic)
                age = self.input_age(topic)
                if msg is not None and age is not None and age <= self.config.sensor_timeout and math.isfinite(msg.data) and msg.data >= 0:
                    best = min(best, float(msg.data))
        return best

    def stop(self) -> bool:
        """Stop the robot now and hold it still for ``stop_hold_time`` s, whatever commands
        arrive meanwhile (an event action: ``Action(method=driver.stop)``); cancels a maneuver."""
        self._maneuver = None
        self._settling = None
        self._held_until = clock.now() + self.config.stop_hold_time
        self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
        # An event action is rare and worth a line: which component stopped the robot, for how long.
        self.get_logger().info("[%s] stop: robot held still for %.1f s", self.component_name, self.config.stop_hold_time)
        return True

    def _drive(self) -> None:
        if clock.now() < self._held_until:
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
            return
        if all(self.input_age(topic) is None for _, _, _, topic in self._mux):
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
            self.health_status.set_healthy()
            return
        blocked = self._blocking_reason()
        if blocked is not None and self._awaiting_first_inputs():
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
            return
        if blocked is not None:
            source, reason = blocked
            self._fail_source(source, f"robot stopped: {reason}")
            self._send(np.zeros(3), ZoneCheck(0.0, math.nan), stop=True)
            self.node.publish_status()
            return
        obstacles, why = self._obstacles()
        if obstacles is None and self._awaiting_first_inputs():
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
            return
        if obstacles is None:
            self.fail_input("sensor_data", f"robot stopped: {why}")
            self._send(np.zeros(3), ZoneCheck(0.0, math.nan), stop=True)
            self.node.publish_status()
            return
        points, lead, history = self._swept_inputs(obstacles)
        if self._command[0] < 0.0:  # backing up: what is behind the laser's field of view counts too
            obstacles = self._all_around(obstacles)
        out, check = self._safety.step(self._command, obstacles, points, self._last_out, lead, history)
        near = self._range_sensors_min()
        if near <= self.config.critical_zone_distance and abs(self._command[0]) > 1e-9:
            out, check = np.zeros(3), ZoneCheck(0.0, near)
            self._safety.filter.reset(np.zeros(3))
        self._send(out, check)
        if self.health_status.is_system_fail or (self.health_status.is_algorithm_fail and not check.emergency_stop):
            self.health_status.set_healthy()
        if check.emergency_stop and self._safety.last_swept.stopped:
            self.fail_algorithm("emergency_stop", self._swept_message(self._command))
        elif check.emergency_stop:
            self.fail_algorithm("emergency_stop", f"obstacle {check.min_distance:.3f} m ahead, inside the critical zone")

    def _swept_message(self, command: np.ndarray) -> str:
        swept = self._safety.last_swept
        what = "even a stop now comes within" if swept.blocked else "would bring the footprint within"
        return (f"swept footprint: command (v {command[0]:.2f} m/s, w {command[2]:.2f} rad/s) {what} "
                f"{self.config.swept_margin:g} m of an obstacle (clearance {swept.clearance:.3f} m): stopped"
                f"{self._keepout_named()}")

    def _send(self, cmd: np.ndarray, check: ZoneCheck, stop: bool = False) -> None:
        if stop:
            self._safety.filter.reset(np.zeros(3))
        topic = self.required_out_topic("robot_command")
        msg: Twist | TwistStamped = twist_msg(cmd)
        if topic.msg_type is TwistStamped:
            # A stamped command keeps the time of the data behind it; otherwise: now.
            stamp = getattr(self, "_command_stamp", None) if not stop else None
            msg = TwistStamped(header=Header(stamp=stamp or clock.stamp(), frame_id=self.config.frames.robot_base), twist=msg)
        self.publish(topic, msg)
        self._last_out = np.array(cmd, dtype=float)
        if self._safety.swept is not None:
            now = clock.now()
            self._sent.append((now, self._last_out))
            cfg = self.config  # the swept check looks back at most this far (and one command more)
            oldest = now - cfg.sensor_timeout - cfg.actuation_latency - 2.0 / cfg.loop_rate
            while len(self._sent) > 1 and self._sent[1][0] <= oldest:
                self._sent.popleft()
        estop = bool(check.emergency_stop) and not stop
        estop_topic = self.get_out_topic("emergency_stop")
        if estop_topic is not None and estop != self._estop:
            self.publish(estop_topic, Bool(data=estop))
            self._estop = estop

    # -- unblock maneuvers ------------------------------------------------------------------------------
    def _start(self, maneuver: M.Maneuver) -> tuple[bool, str]:
        if not maneuver.feasible or maneuver.commands.shape[0] == 0:
            self.fail_algorithm(maneuver.name, f"not possible: {maneuver.reason}")
            return False, maneuver.reason
        self._maneuver = (maneuver, 0)
        self._safety.filter.reset(np.zeros(3))
        message = f"{maneuver.name}: {maneuver.commands.shape[0]} steps" + (f" ({maneuver.reason})" if maneuver.reason else "")
        self.get_logger().info("[%s] maneuver %s", self.component_name, message)
        return True, message

    def _scan_for_maneuver(self) -> Any:
        obstacles, why = self._obstacles()
        if obstacles is None:
            raise BadInput(f"maneuvers need a fresh scan: {why}")
        return self._all_around(obstacles)

    def _run(self, build: Any) -> tuple[bool, str]:
        try:
            ok, message = self._start(build(self._scan_for_maneuver()))
        except BadInput as exc:
            self.fail_input("sensor_data", str(exc))
            return False, str(exc)
        self._settling = None
        if ok and np.any(np.abs(self._last_out) > 1e-3):
            # The base is still moving (a controller's command): the scan and pose this plan
            # was checked on fall behind a robot that turns on. Stop it first, then plan the
            # maneuver again on a scan taken at rest (_play_maneuver): a back-out planned while
            # the robot turns (at 2 rad/s, say) swings its rear into what the laser's rear blind
            # sector hides.
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
            self._settling = (build, clock.now())
        return ok, message

    def _settled(self, stopped_at: float) -> bool:
        """At rest since ``stopped_at`` (node clock): a scan stamped a watchdog period after the
        stop, odometry (if any) that reports no motion; or ``SETTLE_S`` have passed."""
        now = clock.now()
        if now - stopped_at >= SETTLE_S:
            return True
        scans = [self.get_input(t) for t in self.get_in_topics("sensor_data") if t.msg_type is LaserScan]
        if not scans or any(m is None or m.header.stamp.to_sec() < stopped_at + 1.0 / self.config.loop_rate for m in scans):
            return False
        odom = self.latest("location")
        return not isinstance(odom, Odometry) or (abs(odom.twist.twist.linear.x) < 0.02 and abs(odom.twist.twist.angular.z) < 0.05)

    def _move_forward(self) -> tuple[bool, str]:
        return self._run(lambda s: M.move_forward(self.config.robot, s, self.config.max_distance, 1.0 / self.config.loop_rate, self.config.safety_margin))

    def _move_backward(self) -> tuple[bool, str]:
        return self._run(lambda s: M.move_backward(self.config.robot, s, self.config.max_distance, 1.0 / self.config.loop_rate, self.config.safety_margin))

    def _rotate_in_place(self) -> tuple[bool, str]:
        return self._run(lambda s: M.rotate_in_place(self.config.robot, s, self.config.max_rotation, 1.0 / self.config.loop_rate, self.config.safety_margin))

    def _move_to_unblock(self) -> tuple[bool, str]:
        return self._run(lambda s: M.move_to_unblock(self.config.robot, s, self.config.max_distance, self.config.max_rotation,
                                                      1.0 / self.config.loop_rate, self.config.safety_margin))

    def move_forward(self) -> bool:
        """Drive forward up to ``max_distance`` m if the way is clear (an event action)."""
        return self._move_forward()[0]

    def move_backward(self) -> bool:
        return self._move_backward()[0]

    def rotate_in_place(self) -> bool:
        return self._rotate_in_place()[0]

    def move_to_unblock(self) -> bool:
        """Forward, backward or a rotation: the first that frees the robot (an event action)."""
        return self._move_to_unblock()[0]

    def _play_maneuver(self) -> None:
        assert self._maneuver is not None
        if self._settling is not None:
            build, stopped_at = self._settling
            if not self._settled(stopped_at):
                self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
                return
            self._settling = None
            try:
                replanned = build(self._scan_for_maneuver())
            except BadInput as exc:
                replanned = M.Maneuver(self._maneuver[0].name, False, np.zeros((0, 3)), 0.0, str(exc))
            if not replanned.feasible or replanned.commands.shape[0] == 0:
                self._maneuver = None
                self._send(np.zeros(3), ZoneCheck(1.0, math.inf), stop=True)
                self.fail_algorithm(replanned.name, f"not possible once stopped: {replanned.reason}")
                return
            self._maneuver = (replanned, 0)
        maneuver, i = self._maneuver
        if i >= maneuver.commands.shape[0]:
            self._maneuver = None
            self._send(np.zeros(3), ZoneCheck(1.0, math.inf))
            return
        cmd = self._speed_capped(maneuver.commands[i])
        obstacles, _ = self._obstacles()
        check = ZoneCheck(1.0, math.inf)
        swept = None
        if obstacles is not None:
            points, lead, history = self._swept_inputs(obstacles)
            if points is not None:
                cmd, swept = self._safety.limit_swept(cmd, self._last_out, points, lead, history)
        if obstacles is not None and cmd[0] < 0.0:
            obstacles = self._all_around(obstacles)
        if obstacles is not None and abs(cmd[0]) > 1e-9:
            cmd, check = self._safety.zones.limit(cmd, obstacles)
        if obstacles is None or check.emergency_stop or (swept is not None and swept.stopped):
            self._maneuver = None
            self._send(np.zeros(3), check, stop=True)
            why = ("scan went stale" if obstacles is None else "obstacle in the critical zone" if check.emergency_stop
                   else self._swept_message(maneuver.commands[i]))
            self.fail_algorithm(maneuver.name, "aborted: " + why)
            return
        self._maneuver = (maneuver, i + 1)
        self._send(cmd, check)
