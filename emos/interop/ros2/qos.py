"""EMOS's :class:`~emos.config.qos.QoSConfig` as ROS 2 QoS profiles, and back.

The policies have the same names on both sides, so the mapping is one to one:

=================  ==========================  =========================================
QoSConfig field     ROS 2 (rclpy QoSProfile)    note
=================  ==========================  =========================================
``history``         ``history``                 KEEP_LAST / KEEP_ALL / SYSTEM_DEFAULT
``queue_size``      ``depth``                   also the EMOS ring's depth
``reliability``     ``reliability``             RELIABLE / BEST_EFFORT / SYSTEM_DEFAULT
``durability``      ``durability``              VOLATILE / TRANSIENT_LOCAL / SYSTEM_DEFAULT
=================  ==========================  =========================================

Named profiles (``Ros2BridgeConfig.qos`` accepts them for a topic): ``"default"`` (RELIABLE,
VOLATILE, depth 10: rclpy's default), ``"sensor_data"`` (BEST_EFFORT, VOLATILE, depth 5: rclpy's
``qos_profile_sensor_data``), ``"latched"`` (RELIABLE, TRANSIENT_LOCAL, depth 1: what map servers
and ``/tf_static`` publish with, so a node started later still gets the last message).

What the bridge picks when the recipe says nothing (:func:`default_for`): ``latched`` for
``/map``, ``/tf_static``, ``/robot_description`` and names ending in ``/map``; ``default``
otherwise. A RELIABLE publisher serves both RELIABLE and BEST_EFFORT subscribers, which is why
EMOS topics go out RELIABLE by default. Towards EMOS, the bridge subscribes with what every ROS 2
publisher of the topic offers (:func:`matching_subscription`): BEST_EFFORT if any of them is,
TRANSIENT_LOCAL only if all of them are, as ``ros2 bag record`` does.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from emos.config.qos import DurabilityPolicy, HistoryPolicy, QoSConfig, ReliabilityPolicy

PROFILES: dict[str, QoSConfig] = {
    "default": QoSConfig(queue_size=10),
    "sensor_data": QoSConfig(queue_size=5, reliability=ReliabilityPolicy.BEST_EFFORT),
    "latched": QoSConfig(queue_size=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
}
LATCHED_NAMES = frozenset({"/map", "/tf_static", "/robot_description"})


def as_qos(value: Any, what: str = "qos") -> QoSConfig:
    """A QoSConfig from a QoSConfig, a mapping of its fields or a profile name; raises naming ``what``."""
    if isinstance(value, QoSConfig):
        return value
    if isinstance(value, str):
        if value not in PROFILES:
            raise ValueError(f"{what}: unknown QoS profile {value!r}; use one of {', '.join(PROFILES)} or a QoSConfig")
        return PROFILES[value]
    if isinstance(value, dict):
        try:
            return QoSConfig(**value)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{what}: {exc}") from None
    raise ValueError(f"{what}: expected a QoSConfig, its fields as a dict, or a profile name, got {value!r}")


def default_for(topic: str) -> QoSConfig:
    if topic in LATCHED_NAMES or topic.endswith("/map"):
        return PROFILES["latched"]
    return PROFILES["default"]


def to_ros(qos: QoSConfig) -> Any:
    """The rclpy ``QoSProfile`` of a QoSConfig (rclpy must be importable)."""
    from rclpy.qos import DurabilityPolicy as D
    from rclpy.qos import HistoryPolicy as H
    from rclpy.qos import QoSProfile
    from rclpy.qos import ReliabilityPolicy as R

    history = {HistoryPolicy.KEEP_LAST: H.KEEP_LAST, HistoryPolicy.KEEP_ALL: H.KEEP_ALL, HistoryPolicy.SYSTEM_DEFAULT: H.SYSTEM_DEFAULT}
    reliability = {ReliabilityPolicy.RELIABLE: R.RELIABLE, ReliabilityPolicy.BEST_EFFORT: R.BEST_EFFORT,
                   ReliabilityPolicy.SYSTEM_DEFAULT: R.SYSTEM_DEFAULT}
    durability = {DurabilityPolicy.VOLATILE: D.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL: D.TRANSIENT_LOCAL,
                  DurabilityPolicy.SYSTEM_DEFAULT: D.SYSTEM_DEFAULT}
    profile: Any = QoSProfile  # rclpy's constructor is untyped
    return profile(history=history[qos.history], depth=qos.queue_size, reliability=reliability[qos.reliability],
                      durability=durability[qos.durability])


def matching_subscription(publisher_profiles: Iterable[Any], depth: int = 10) -> QoSConfig:
    """The QoS that hears every publisher of ``publisher_profiles`` (rclpy QoSProfiles)."""
    from rclpy.qos import DurabilityPolicy as D
    from rclpy.qos import ReliabilityPolicy as R

    profiles = list(publisher_profiles)
    best_effort = any(p.reliability == R.BEST_EFFORT for p in profiles)
    latched = bool(profiles) and all(p.durability == D.TRANSIENT_LOCAL for p in profiles)
    return QoSConfig(queue_size=depth, reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def describe(qos: QoSConfig) -> str:
    return f"{qos.reliability.value}/{qos.durability.value}/depth {qos.queue_size}"
