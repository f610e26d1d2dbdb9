"""``RobotPlugin``: the component a robot plugin runs as, supervised like any other.

A plugin is a subclass that declares (class attributes, :mod:`.declare`)::

    feedback = {"odom": Feedback(msg_type="Odometry", topic="/odom"), ...}     # device -> topics
    commands = {"command": Command(msg_types=("Twist",), topic="/cmd_vel", timeout="cmd_timeout")}
    plugin_events = {"bump": PluginEvent(feedback="bumper", condition=lambda t: t.msg.data == True)}

and implements ``make_transports()`` (name -> :mod:`.transports` object, built from its attrs
config; nothing is opened there) and the hooks it needs:

* ``on_open(name, transport)``: the handshake after each (re)open (Start, Safe, stream request);
* ``on_data(name, data)``: bytes received (decoders; publish with :meth:`emit`);
* ``on_command(key, msg)``: a command message (encoders; write with :meth:`send`);
* ``on_command_timeout(key)``: no fresh command for the key's watchdog period (once per silence);
* ``on_poll()``: once per poll, after the data (safety checks, periodic feedback);
* ``on_lost(name, transport)``: the link just went down (a last stop, if it still listens);
* ``on_close()``: before the transports close on deactivate/shutdown.

The runtime here does the rest, the same for every plugin: keyed topics (``plugin.inputs(command=
...)``, ``plugin.outputs(odom=...)``, the Simulator's keys where they mean the same, so a recipe
swaps the Simulator for a plugin by one line); an Event run type triggered by the command
topics (a command is encoded and written in the step its message arrives in) and a poll timer
at ``loop_rate`` (a Timed step when there are no commands); the command watchdogs; heartbeat
timers; health every poll: SYSTEM_FAILURE naming the device while a transport is lost,
COMPONENT_FAILURE with :attr:`device_problem` (a servo that does not answer), else HEALTHY;
the reconnect ladder (:class:`emos.core.retry.Backoff` delays) with the handshake replayed; a
device missing or taken at start fails activation with its name, and the status says
SYSTEM_FAILURE with the same words. Plugin actions are public methods marked with
:func:`.declare.plugin_action`; :meth:`event` turns a declared event into an
:class:`~emos.events.Event` for the recipe's ``events_actions``.
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, ClassVar

import attrs
from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig, ComponentRunType
from emos.core.conventions import AllowedTopic
from emos.core.keyed import KeyedComponent
from emos.core.retry import Backoff
from emos.io.topic import Topic
from emos.ratelimit import RateLimitedLog

from .declare import Command, Feedback, PluginEvent
from .transports import SessionTransport, Transport

__all__ = ["PluginConfig", "RobotPlugin"]


@define(kw_only=True)
class PluginConfig(BaseComponentConfig):
    """What every plugin has: the poll rate (``loop_rate``) and its reconnect ladder."""

    reconnect_first_s: float = field(default=0.05, converter=float, validator=V.finite_positive)
    reconnect_max_s: float = field(default=2.0, converter=float, validator=V.finite_positive)


class RobotPlugin(KeyedComponent):
    """Base of every robot plugin (module docstring)."""

    plugin_name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    feedback: ClassVar[Mapping[str, Feedback]] = {}
    commands: ClassVar[Mapping[str, Command]] = {}
    plugin_events: ClassVar[Mapping[str, PluginEvent]] = {}
    plugin_actions: ClassVar[Mapping[str, str]] = {}  # name -> help, collected from @plugin_action methods

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.allowed_inputs = {key: AllowedTopic(types=c.msg_types, default=Topic(name=c.topic, msg_type=c.msg_types[0]))
                              for key, c in cls.commands.items()}
        cls.allowed_outputs = {key: AllowedTopic(types=(f.msg_type,), default=Topic(name=f.topic, msg_type=f.msg_type))
                               for key, f in cls.feedback.items()}
        for name, ev in cls.plugin_events.items():
            if ev.feedback not in cls.feedback:
                raise TypeError(f"{cls.__name__}: event {name!r} watches feedback {ev.feedback!r}, which the plugin "
                                f"does not declare (it has {sorted(cls.feedback)})")
        for key, c in cls.commands.items():
            if c.timeout is not None and c.timeout not in {f.name for f in attrs.fields(cls.config_class())}:
                raise TypeError(f"{cls.__name__}: command {key!r} has its watchdog in config field {c.timeout!r}, "
                                f"which {cls.config_class().__name__} does not have")
        cls.plugin_actions = {name: getattr(cls, name)._emos_plugin_action for name in dir(cls)
                              if not name.startswith("_") and hasattr(getattr(cls, name, None), "_emos_plugin_action")}

    def __init__(self, component_name: str, config: PluginConfig | None = None, *,
                 inputs: Mapping[str, Topic] | None = None, outputs: Mapping[str, Topic] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(component_name, inputs=inputs, outputs=outputs, config=config, **kwargs)
        if self.commands:  # a command is written in the step its message arrives in
            self.trigger = [t for key in self.commands for t in self.get_in_topics(key)]
        else:
            self.run_type = ComponentRunType.TIMED
        self.transports: dict[str, Transport] = {}
        self.device_problem: str = ""  # set by a plugin for a COMPONENT failure (a servo not answering)
        self._device_error = ""
        self._timed_out: set[str] = set()
        self._failures: dict[str, int] = {}
        self._next_try: dict[str, float] = {}
        self._rlog = RateLimitedLog(self._logger, interval=5.0)

    @classmethod
    def config_class(cls) -> type[PluginConfig]:
        return PluginConfig

    # -- what a plugin implements ------------------------------------------------------------------
    def make_transports(self) -> Mapping[str, Transport]:
        raise NotImplementedError(f"{type(self).__name__} must implement make_transports()")

    def heartbeats(self) -> list[Any]:
        """Keep-alives (:class:`.declare.Heartbeat`) to run while the transports are up."""
        return []

    @classmethod
    def robot_config(cls) -> Any:
        """The RobotConfig (``emos.actors.nav.RobotConfig``) of the robot this plugin drives, or None."""
        return None

    def on_open(self, name: str, transport: Transport) -> None:
        pass

    def on_data(self, name: str, data: bytes) -> None:
        pass

    def on_command(self, key: str, msg: Any) -> None:
        pass

    def on_command_timeout(self, key: str) -> None:
        pass

    def on_poll(self) -> None:
        pass

    def on_lost(self, name: str, transport: Transport) -> None:
        pass

    def on_reconnected(self, name: str, transport: Transport) -> None:
        pass

    def on_close(self) -> None:
        pass

    # -- what a plugin calls -----------------------------------------------------------------------
    def emit(self, key: str, msg: Any) -> None:
        """Publish ``msg`` on the topic(s) of feedback ``key``."""
        for topic in self.get_out_topics(key):
            self.publish(topic, msg)

    def send(self, name: str, data: bytes) -> float | None:
        """Write ``data`` to transport ``name``: the time it was handed over, None if it is down."""
        transport = self.transports.get(name)
        return transport.write(data) if transport is not None else None

    def event(self, name: str, **overrides: Any) -> Any:
        """The declared plugin event ``name`` as an :class:`~emos.events.Event` on this plugin's
        topic (``Event`` keyword arguments override the declaration's)."""
        from emos.events import Event

        spec = self.plugin_events.get(name)
        if spec is None:
            raise KeyError(f"plugin {self.component_name!r} ({type(self).__name__}) has no event {name!r}; "
                           f"its events are: {', '.join(sorted(self.plugin_events)) or 'none'}")
        topic = self.get_out_topic(spec.feedback)
        kwargs = {"on_change": spec.on_change, "keep_event_delay": spec.keep_event_delay,
                  "name": f"{self.component_name}.{name}", **overrides}
        return Event(spec.condition(topic), **kwargs)

    # -- lifecycle ---------------------------------------------------------------------------------
    def custom_on_activate(self) -> None:
        transports = dict(self.make_transports())
        opened: list[Transport] = []
        try:
            for name, transport in transports.items():
                transport.open()  # DeviceError (or the driver's own error) names the device
                opened.append(transport)
                self.on_open(name, transport)
        except Exception as exc:
            self._device_error = str(exc)
            for transport in opened:
                transport.close()
            raise
        self.transports = transports
        self._timed_out.clear()
        self._failures = {name: 0 for name in transports}
        if self.commands:
            self.create_timer(1.0 / self.config.loop_rate, self._poll)
        for hb in self.heartbeats():
            self.create_timer(hb.period, lambda hb=hb: self._beat(hb))

    def custom_on_error(self) -> bool:
        """A failed activation because of the device is a SYSTEM failure naming it."""
        if self._device_error:
            self.health_status.set_fail_system(topic_names=[t.name for t in self.out_topics], message=self._device_error)
            self._device_error = ""
        return True

    def custom_on_deactivate(self) -> None:
        transports, self.transports = self.transports, {}
        if transports:
            self.on_close()
        for transport in transports.values():
            transport.close()

    def custom_on_shutdown(self) -> None:
        self.custom_on_deactivate()

    # -- steps -------------------------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        if not self.commands:
            self._poll()
            return
        if msg is None or topic is None or not self.transports:
            return
        key = self.in_key_of(topic)
        if key is None:
            return
        self._timed_out.discard(key)
        self.on_command(key, msg)
        self._update_health()

    def _poll(self) -> None:
        if not self.transports:
            return
        down = False
        for name, transport in self.transports.items():
            lost = transport.poll_lost() if isinstance(transport, SessionTransport) else transport.lost
            if lost is not None:
                self._recover(name, transport)
                down = True
                continue
            data = transport.take()
            if data:
                self.on_data(name, data)
        if not down:
            self.on_poll()
            self._watchdogs()
        self._update_health()

    def _watchdogs(self) -> None:
        for key, command in self.commands.items():
            if command.timeout is None or key in self._timed_out:
                continue
            limit = getattr(self.config, command.timeout)
            ages = [self.input_age(t) for t in self.get_in_topics(key)]
            fresh = [a for a in ages if a is not None]
            if not fresh or min(fresh) > limit:
                self._timed_out.add(key)  # once per silence: a fresh command re-arms it
                self.on_command_timeout(key)

    def _beat(self, hb: Any) -> None:
        transport = self.transports.get(hb.transport)
        if transport is not None and transport.lost is None:
            transport.write(hb.payload)

    def _update_health(self) -> None:
        lost = [t.lost for t in self.transports.values() if t.lost is not None]
        if lost:
            self.health_status.set_fail_system(topic_names=[t.name for t in self.out_topics], message="; ".join(lost))
        elif self.device_problem:
            self.health_status.set_fail_component(component_names=[self.component_name], message=self.device_problem)
        else:
            self.health_status.set_healthy()

    def _recover(self, name: str, transport: Transport) -> None:
        """The reconnect ladder of one transport: SYSTEM_FAILURE naming the device at once, a last
        stop if it still listens, then reopen on Backoff delays and replay the handshake."""
        cfg: Any = self.config  # a PluginConfig (config_class)
        if self._failures.get(name, 0) == 0 and name not in self._next_try:
            self.get_logger().error("[%s] %s", self.component_name, transport.lost)
            self.on_lost(name, transport)
            self.health_status.set_fail_system(topic_names=[t.name for t in self.out_topics], message=transport.lost or name)
            if self._node is not None:
                self.health_status_publisher.publish(self.health_status())
            self._next_try[name] = time.monotonic()
        # A driver session runs its own ladder (it knows when to retry): ask it every poll.
        if not isinstance(transport, SessionTransport) and time.monotonic() < self._next_try[name]:
            return
        self._failures[name] = self._failures.get(name, 0) + 1
        if transport.reconnect():
            if not isinstance(transport, SessionTransport):
                self.on_open(name, transport)
            self.get_logger().info("[%s] %s %s back after %d attempt(s)", self.component_name, transport.device,
                                   transport.address, self._failures[name])
            self._failures[name] = 0
            self._next_try.pop(name, None)
            self.on_reconnected(name, transport)
            return
        ladder = Backoff(base=cfg.reconnect_first_s, factor=2.0, cap=cfg.reconnect_max_s, timeout=1e9)
        self._next_try[name] = time.monotonic() + ladder.delay(self._failures[name])
        self._rlog.warning(("reconnect", name), "[%s] %s", self.component_name, transport.lost)
