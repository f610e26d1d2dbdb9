"""What every navigation component shares: the robot and its frames in the config, keyed
inputs read by key, and rate-limited reports of bad or missing input."""
from __future__ import annotations

from typing import Any

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig, ComponentRunType
from emos.core.keyed import KeyedComponent, key_name
from emos.errors import ConfigError
from emos.geometry import PoseHistory
from emos.io.topic import Topic
from emos.ratelimit import RateLimitedLog

from ..robot import RobotConfig, RobotFrames, RobotGeometry, RobotType
from .convert import BadInput, pose_of, velocity_of

__all__ = ["NavComponentConfig", "NavComponent", "default_robot"]

_STAMPED_LOCATIONS = ("Odometry", "PoseStamped", "PoseWithCovarianceStamped")


def default_robot() -> RobotConfig:
    """A small differential-drive robot (radius 0.1 m): what a config holds until the recipe
    sets ``launcher.robot`` or ``config.robot``."""
    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.1, 0.3]))


@define(kw_only=True)
class NavComponentConfig(BaseComponentConfig):
    """``robot``: kinematics, footprint and limits; ``frames``: frame names (both set for every
    component at once by ``launcher.robot`` / ``launcher.frames``)."""

    robot: RobotConfig = field(factory=default_robot, validator=V.instance_of(RobotConfig))
    frames: RobotFrames = field(factory=RobotFrames, validator=V.instance_of(RobotFrames))


class NavComponent(KeyedComponent):
    """A keyed component with helpers to read inputs by key."""

    config: NavComponentConfig

    # How many location messages a component that looks poses up by stamp keeps (odometry at
    # 50 Hz: 1.3 s), and how far before the oldest a stamp may lie and still be clamped to it:
    # further, the two inputs' clocks do not agree, and the latest pose is the better guess.
    LOCATION_CACHE = 64
    LOCATION_STAMP_SLACK_S = 0.5

    def __init__(self, component_name: str, config: NavComponentConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        self._report = RateLimitedLog(interval=5.0)  # logs to get_logger(), given per call
        self._location_history: PoseHistory | None = None

    @classmethod
    def config_class(cls) -> type[NavComponentConfig]:
        return NavComponentConfig

    # -- reading inputs by key ---------------------------------------------------------------------
    def latest(self, key: Any) -> Any | None:
        """The latest message of the (first) topic of ``key``; None if the key has no topic or
        nothing arrived yet."""
        topic = self.get_in_topic(key)
        return None if topic is None else self.get_input(topic)

    def age_of(self, key: Any) -> float | None:
        """Seconds since the last message of ``key`` (None: nothing yet, or no topic)."""
        topic = self.get_in_topic(key)
        return None if topic is None else self.input_age(topic)

    def topic_name(self, key: Any) -> str:
        topic = self.get_in_topic(key)
        return topic.name if topic is not None else str(key)

    def default_trigger(self, key: Any) -> None:
        """An event-driven component given no trigger steps on each message of ``key`` (called
        when it configures). Without a topic on that key it could never step: a clear error."""
        if self.run_type != ComponentRunType.EVENT or self._trigger:
            return
        topic = self.get_in_topic(key)
        if topic is None:
            raise ConfigError(f"component {self.component_name!r} ({type(self).__name__}) runs on events but has no "
                              f"trigger and no {key_name(key)!r} input to step on: give it that input or a trigger")
        self._trigger = [topic]

    def required_out_topic(self, key: Any) -> Topic:
        """The topic of an output key declared ``required`` (the launcher starts no component
        without one, so only a component run by hand can lack it: a clear error then)."""
        topic = self.get_out_topic(key)
        if topic is None:
            raise ConfigError(f"component {self.component_name!r} ({type(self).__name__}) has no topic on its "
                              f"required output {key_name(key)!r}")
        return topic

    def robot_state(self, max_age: float | None = None) -> tuple[np.ndarray, np.ndarray | None] | None:
        """(pose, body velocity or None) from the ``location`` input; None (and a SYSTEM failure
        naming the topic) when it is missing, older than ``max_age`` s, or not finite."""
        msg = self.latest("location")
        name = self.topic_name("location")
        if msg is None:
            self.fail_input("location", f"no message on {name} yet")
            return None
        age = self.age_of("location")
        if max_age is not None and age is not None and age > max_age:
            self.fail_input("location", f"{name} is stale: last message {age:.2f} s ago (limit {max_age:g} s)")
            return None
        try:
            return pose_of(msg), velocity_of(msg)
        except BadInput as exc:
            self.fail_input("location", f"{name}: {exc}")
            return None

    def cache_location(self) -> None:
        """Keep the recent messages of the ``location`` input, for :meth:`location_at` (call in
        ``custom_on_configure``; without a location topic, nothing to keep)."""
        topic = self.get_in_topic("location")
        if topic is not None and topic.msg_type.__name__ in _STAMPED_LOCATIONS:  # a bare Pose has no time
            self.node.cache_input(topic, self.LOCATION_CACHE)
            self._location_history = PoseHistory()

    def location_at(self, stamp: float) -> np.ndarray | None:
        """The ``location`` input's pose at ``stamp`` (s, the clock of the messages' headers),
        interpolated between the messages around it, as tf2 looks a transform up at a scan's
        time: a component that runs behind pairs each scan with where the robot was when it was
        taken, not with the latest odometry. The latest pose when the input is not cached, the
        stamp is unset (0) or lies more than ``LOCATION_STAMP_SLACK_S`` before the oldest kept
        (clocks that do not agree: reported); the newest when the stamp is newer than all.
        None (and a SYSTEM failure naming the topic) when there is no usable location yet."""
        history = self._location_history
        if history is not None:
            for t, pose in self._new_locations(history):
                history.add(t, pose)
        held = history.span_times if history is not None else None
        if history is None or held is None or stamp <= 0.0:
            state = self.robot_state()
            return None if state is None else state[0]
        if stamp < held[0] - self.LOCATION_STAMP_SLACK_S:
            self._report.warning("location:clock", "[%s] a message stamped %.3f s is %.2f s older than the oldest of "
                                 "%s kept (%.3f s): the two clocks do not agree; using the latest pose",
                                 self.component_name, stamp, held[0] - stamp, self.topic_name("location"), held[0],
                                 logger=self.get_logger())
            return history.at(held[1])
        return history.at(stamp)

    def _new_locations(self, history: PoseHistory) -> list[tuple[float, np.ndarray]]:
        """The cached location messages newer than ``history``'s newest, as (stamp, pose); a
        message with a bad pose or no stamp is reported and skipped."""
        topic = self.get_in_topic("location")
        held = history.span_times
        newest = held[1] if held is not None else -np.inf
        fresh: list[tuple[float, np.ndarray]] = []
        for msg in reversed(self.node.cached(topic) if topic is not None else []):
            header = getattr(msg, "header", None)
            t = header.stamp.to_sec() if header is not None else 0.0
            if t <= 0.0:
                continue  # an unset stamp: it cannot be placed in time
            if t <= newest:
                break
            try:
                fresh.append((t, pose_of(msg)))
            except BadInput as exc:
                self.fail_input("location", f"{self.topic_name('location')}: {exc}")
        return fresh[::-1]

    # -- reporting -----------------------------------------------------------------------------------
    def fail_input(self, key: Any, message: str) -> None:
        """An input is missing, stale or malformed: SYSTEM failure naming its topic."""
        self.health_status.set_fail_system(topic_names=[self.topic_name(key)], message=message)
        self._report.warning(f"input:{key}", "[%s] %s", self.component_name, message, logger=self.get_logger())

    def fail_algorithm(self, algorithm: str, message: str) -> None:
        self.health_status.set_fail_algorithm(algorithm_names=[algorithm], message=message)
        self._report.warning(f"algo:{algorithm}:{message[:40]}", "[%s] %s: %s", self.component_name, algorithm, message,
                             logger=self.get_logger())


def rate_field(default: float) -> Any:
    """A ``loop_rate`` field with the component's own default (Hz), validated like the base's."""
    from emos.config.validators import in_range

    return field(default=default, validator=in_range(min_value=1e-9, max_value=1e9))
