"""What every navigation component shares: the robot and its frames in the config, keyed
inputs read by key, and rate-limited reports of bad or missing input."""
from __future__ import annotations

import time
from typing import Any

import attrs
import numpy as np
from attrs import define, field

from emos.config.base import BaseComponentConfig
from emos.core.keyed import KeyedComponent

from ..robot import RobotConfig, RobotFrames, RobotGeometry, RobotType
from .convert import BadInput, pose_of, velocity_of

__all__ = ["NavComponentConfig", "NavComponent", "default_robot"]


def default_robot() -> RobotConfig:
    """A small differential-drive robot (radius 0.1 m): what a config holds until the recipe
    sets ``launcher.robot`` or ``config.robot``."""
    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.1, 0.3]))


def _instance(cls: type):
    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        if not isinstance(value, cls):
            raise TypeError(f"{type(instance).__name__}.{attribute.name}: expected a {cls.__name__}, got {type(value).__name__} {value!r}")

    return check


@define(kw_only=True)
class NavComponentConfig(BaseComponentConfig):
    """``robot``: kinematics, footprint and limits; ``frames``: frame names (both set for every
    component at once by ``launcher.robot`` / ``launcher.frames``)."""

    robot: RobotConfig = field(factory=default_robot, validator=_instance(RobotConfig))
    frames: RobotFrames = field(factory=RobotFrames, validator=_instance(RobotFrames))


class _RateLimited:
    """Log the first occurrence of a problem at once, then at most every ``period`` s with a count."""

    def __init__(self, period: float = 5.0) -> None:
        self.period = period
        self._seen: dict[str, tuple[float, int]] = {}

    def __call__(self, log: Any, level: int, key: str, message: str) -> None:
        now = time.monotonic()
        last, count = self._seen.get(key, (-1e18, 0))
        count += 1
        if now - last >= self.period:
            suffix = f" ({count} times in the last {self.period:g} s)" if count > 1 else ""
            log.log(level, "%s%s", message, suffix)
            self._seen[key] = (now, 0)
        else:
            self._seen[key] = (last, count)


class NavComponent(KeyedComponent):
    """A keyed component with helpers to read inputs by key."""

    config: NavComponentConfig

    def __init__(self, component_name: str, config: NavComponentConfig | None = None, **kwargs: Any) -> None:
        config_cls = type(self).config_class()
        if config is None:
            config = config_cls()
        elif not isinstance(config, config_cls):
            raise TypeError(f"component {component_name!r} ({type(self).__name__}): config must be a {config_cls.__name__}, got {type(config).__name__}")
        super().__init__(component_name, config=config, **kwargs)
        self._report = _RateLimited()

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
        import logging

        self.health_status.set_fail_system(topic_names=[self.topic_name(key)], message=message)
        self._report(self.get_logger(), logging.WARNING, f"input:{key}", f"[{self.component_name}] {message}")

    def fail_algorithm(self, algorithm: str, message: str) -> None:
        import logging

        self.health_status.set_fail_algorithm(algorithm_names=[algorithm], message=message)
        self._report(self.get_logger(), logging.WARNING, f"algo:{algorithm}:{message[:40]}", f"[{self.component_name}] {algorithm}: {message}")


def rate_field(default: float) -> Any:
    """A ``loop_rate`` field with the component's own default (Hz), validated like the base's."""
    from emos.config.validators import in_range

    return field(default=default, validator=in_range(min_value=1e-9, max_value=1e9))
