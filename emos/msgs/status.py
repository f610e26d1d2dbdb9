"""ComponentStatus: the health report every component publishes on ``<component>/status``."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type
from emos.msgs.std import Header


@message_type("sugar")
class ComponentStatus(Message):
    STATUS_HEALTHY = 0
    STATUS_FAILURE_ALGORITHM_LEVEL = 1
    STATUS_FAILURE_COMPONENT_LEVEL = 2
    STATUS_FAILURE_SYSTEM_LEVEL = 3
    STATUS_GENERAL = 4

    header: Header = F.message(Header)
    status: int = F.integer(bits=8, signed=False)
    # What failed: algorithm names, sub-component names or topic names, by level.
    src_algorithms: list[str] = F.string_list()
    src_components: list[str] = F.string_list()
    src_topics: list[str] = F.string_list()
    message: str = F.string()
    # Lifecycle state name and pid of the sender, so the supervisor and `emos status` see both.
    lifecycle_state: str = F.string()
    pid: int = F.integer(bits=32)
