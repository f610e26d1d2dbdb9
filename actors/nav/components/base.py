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
from emos.io.topic import Topic
from emos.ratelimit import RateLimitedLog

from ..robot import RobotConfig, RobotFrames, RobotGeometry, RobotType
from .convert import BadInput, pose_of, velocity_of

__all__ = ["NavComponentConfig", "NavComponent", "default_robot"]


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

    def __init__(self, component_name: str, config: NavComponentConfig | None = None, **kwargs: Any) -> None:
        super().__init__(component_name, config=config, **kwargs)
        self._report = RateLimitedLog(interval=5.0)  # logs to get_logger(), given per call

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
