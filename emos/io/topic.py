"""``Topic``: the name, message type, QoS and freshness of one stream of data."""
from __future__ import annotations

import re
from typing import Any

from attrs import define, field

from emos.config.base import BaseAttrs
from emos.config.qos import QoSConfig
from emos.msgs.registry import canonical_name, resolve
from emos.transport.limits import check_topic_name

_NAME_RE = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$")


def normalize_topic_name(name: str) -> str:
    """ROS semantics: ``scan`` and ``/scan`` are the same topic; names are validated here."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"Topic name must be a non-empty string, got {name!r}")
    name = name.strip()
    if not _NAME_RE.match(name):
        if "~" in name or "{" in name:
            # ROS expands these in the node's context; EMOS names are global and never expanded,
            # so '~scan' would be a different topic from the one a ROS user means.
            raise ValueError(f"Topic name {name!r} is invalid: ROS substitutions ('~' for the node's namespace, "
                             "'{...}') are not expanded by EMOS; write the full name, e.g. '/robot/scan'")
        raise ValueError(
            f"Topic name {name!r} is invalid: use letters, digits and '_', separated by '/', "
            "not starting with a digit and without '//' or a trailing '/'"
        )
    name = name if name.startswith("/") else "/" + name
    check_topic_name(name)
    return name


def _qos(value: Any) -> QoSConfig:
    if value is None:
        return QoSConfig()
    if isinstance(value, QoSConfig):
        return value
    if isinstance(value, dict):
        return QoSConfig(**value)
    raise TypeError(f"Topic qos_profile must be a QoSConfig, got {type(value).__name__}")


def _msg_type(value: Any) -> type:
    return resolve(value)  # raises UnknownMessageType listing close matches


@define(kw_only=True, eq=False)
class Topic(BaseAttrs):
    """``Topic(name="scan", msg_type="LaserScan", qos_profile=QoSConfig(...), data_timeout=0.5)``.

    ``msg_type`` is a message class or its name; an unknown name fails here, at definition.
    ``data_timeout`` (seconds, 0 = never stale) is how old the last message may be before the
    topic's data counts as stale for events and input checks.
    """

    name: str = field(converter=normalize_topic_name)
    msg_type: type = field(converter=_msg_type)
    qos_profile: QoSConfig = field(factory=QoSConfig, converter=_qos)
    data_timeout: float = field(default=0.0)
    # "auto" (the run option decides, shared memory unless `emos run --net-topics`), "shm" or
    # "zenoh" (across hosts), or "ros2" (on the ROS 2 graph from the component's own process,
    # emos.interop.ros2.direct): see emos.transport.select.
    transport: str = field(default="auto")

    @transport.validator
    def _check_transport(self, attribute: Any, value: Any) -> None:
        from emos.transport.select import TRANSPORTS

        if value not in TRANSPORTS:
            raise ValueError(f"Topic {self.name!r}: transport must be one of {TRANSPORTS}, got {value!r}")
        if value == "ros2":  # without ROS 2, fail here, at definition, with what to install
            from emos.interop.ros2 import env

            try:
                env.require()
            except env.Ros2Unavailable as exc:
                raise env.Ros2Unavailable(f"Topic {self.name!r} (transport='ros2'): {exc}") from None

    @data_timeout.validator
    def _check_timeout(self, attribute: Any, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ValueError(f"Topic {self.name!r}: data_timeout must be a number of seconds >= 0, got {value!r}")

    @property
    def type_name(self) -> str:
        return canonical_name(self.msg_type)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Topic) and (self.name, self.msg_type) == (other.name, other.msg_type)

    def __hash__(self) -> int:  # type: ignore[override]
        return hash((self.name, self.msg_type))

    def to_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "msg_type": self.type_name, "qos_profile": self.qos_profile.asdict(), "data_timeout": self.data_timeout}
        if self.transport != "auto":  # only when set: dicts of existing recipes stay as they were
            out["transport"] = self.transport
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Topic:
        return cls(**data)

    def __repr__(self) -> str:
        return f"Topic(name={self.name!r}, msg_type={self.type_name!r})"

    # -- event conditions (emos.events.conditions): ``topic.msg.data < 20.0``, ``topic & cond``
    @property
    def msg(self) -> Any:
        """The root of an event condition or action binding over this topic's messages."""
        from emos.events.conditions import MsgPath

        return MsgPath(self)

    def __and__(self, other: Any) -> Any:
        from emos.events.conditions import new_message

        return new_message(self) & other

    def __or__(self, other: Any) -> Any:
        from emos.events.conditions import new_message

        return new_message(self) | other
