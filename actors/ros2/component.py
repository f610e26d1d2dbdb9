"""``Ros2BridgeComponent``: the only process of a run that holds an rclpy node.

``emos run --ros2`` (or a recipe's ``emos.transport.select.use_ros2(...)``) adds one to the run
as its own supervised group; a recipe may also add it itself like any component. When it dies
(SIGKILL included) the supervisor restarts it and the bridged streams resume; it talks UDP only
by default (Fast DDS's shared-memory files would outlive a SIGKILL; ``fastdds="shm"`` trades
that for speed with large messages, docs/ros2.md).
"""
from __future__ import annotations

from typing import Any

from attrs import define, field

from emos.config import validators
from emos.config.base import BaseComponentConfig
from emos.core.component import BaseComponent


def _topics(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
        raise ValueError(f"Ros2BridgeConfig.topics must be a list of topic names or wildcards (empty: all), got {value!r}")


def _domain(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.ros2.options import check_domain

    try:
        check_domain(value)
    except ValueError as exc:
        raise ValueError(f"Ros2BridgeConfig.domain_id: {exc}") from None


def _qos(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.ros2.qos import as_qos

    if not isinstance(value, dict):
        raise ValueError(f"Ros2BridgeConfig.qos must map topic names to a QoSConfig or profile name, got {value!r}")
    for topic, q in value.items():
        as_qos(q, f"Ros2BridgeConfig.qos[{topic!r}]")


def _fastdds(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.ros2.fastdds import FASTDDS_TRANSPORTS

    if value not in FASTDDS_TRANSPORTS:
        raise ValueError(f"Ros2BridgeConfig.fastdds must be one of {', '.join(FASTDDS_TRANSPORTS)}, got {value!r}")


def _node_name(instance: Any, attribute: Any, value: Any) -> None:
    import re

    if not isinstance(value, str) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", value):
        raise ValueError(f"Ros2BridgeConfig.node_name must be a ROS 2 node name (letters, digits, '_'), got {value!r}")


@define(kw_only=True)
class Ros2BridgeConfig(BaseComponentConfig):
    """``topics``: names or wildcards to bridge (empty: every topic of shared type on both sides).
    ``domain_id``: the ROS 2 domain (None: ``$ROS_DOMAIN_ID``, else 0). ``qos``: per topic, a
    QoSConfig or ``"default"`` / ``"sensor_data"`` / ``"latched"`` (docs/ros2.md). ``fastdds``:
    ``"udp"`` (loopback UDP only: nothing left behind by a SIGKILL) or ``"shm"`` (Fast DDS's
    default transports, shared memory towards local nodes: faster for large messages)."""

    loop_rate: float = field(default=2.0, validator=validators.in_range(min_value=1e-3, max_value=1e3))
    topics: list = field(factory=list, validator=_topics)
    domain_id: int | None = field(default=None, validator=_domain)
    node_name: str = field(default="emos_bridge", validator=_node_name)
    qos: dict = field(factory=dict, validator=_qos)
    fastdds: str = field(default="udp", validator=_fastdds)


def config_from_environment() -> Ros2BridgeConfig:
    """The bridge ``emos run --ros2 --ros2-topics ... --ros-domain-id N`` asked for."""
    from emos.interop.ros2.options import from_environment

    _enabled, topics, domain = from_environment()
    return Ros2BridgeConfig(topics=topics, domain_id=domain)


class Ros2BridgeComponent(BaseComponent):
    """Bridges the run's topics to the ROS 2 graph (see :class:`emos.interop.ros2.bridge.Ros2Bridge`)."""

    @classmethod
    def config_class(cls) -> type[Ros2BridgeConfig]:
        return Ros2BridgeConfig

    def __init__(self, component_name: str = "ros2_bridge", config: Ros2BridgeConfig | None = None, **kwargs: Any) -> None:
        from emos.interop.ros2 import env

        env.require()  # no ROS 2: fail here, where the recipe asks for the bridge, saying what to install
        super().__init__(component_name, config=config or Ros2BridgeConfig(), **kwargs)
        self.config: Ros2BridgeConfig
        self.bridge: Any = None

    def custom_on_activate(self) -> None:
        from emos.interop.ros2.bridge import Ros2Bridge

        cfg = self.config
        self.bridge = Ros2Bridge(self.node.ctx, cfg.topics or None, domain_id=cfg.domain_id, node_name=cfg.node_name, qos=cfg.qos,
                                 fastdds=cfg.fastdds)
        self.get_logger().info("ROS 2: %s, domain %d, node /%s", self.bridge.install.describe(), self.bridge.domain_id, cfg.node_name)

    def _execution_step(self, **kwargs: Any) -> None:
        if self.bridge is not None and not self.bridge.alive():
            self.health_status.set_fail_component(message=f"ROS 2 bridge stopped: {self.bridge.failure or 'a thread ended'}")
            return
        self.health_status.set_healthy()

    def served_interfaces(self) -> list[tuple[str, str, tuple[Any, ...]]]:
        """The ROS 2 services and actions offered to EMOS: ``emos service call`` and ``emos action
        send_goal`` reach them through the bridge like any component's."""
        if self.bridge is None:
            return []
        return self.bridge.served_interfaces()

    def custom_on_deactivate(self) -> None:
        self._close()

    def custom_on_shutdown(self) -> None:
        self._close()

    def _close(self) -> None:
        if self.bridge is not None:
            bridge, self.bridge = self.bridge, None
            bridge.close()
