"""Quality-of-service settings of a topic, with the ROS names recipes already use.

On shared-memory rings: ``queue_size`` is the ring depth and each subscriber's backlog;
``TRANSIENT_LOCAL`` lets a late subscriber receive the last ``queue_size`` messages;
``RELIABLE`` and ``BEST_EFFORT`` behave the same (a ring never blocks its writer; a subscriber that
falls a whole ring behind counts the messages it missed in ``dropped``).
"""
from __future__ import annotations

from enum import Enum

from attrs import define, field

from emos.config.base import BaseAttrs, enum_converter
from emos.config.validators import in_range


class HistoryPolicy(str, Enum):
    KEEP_LAST = "KEEP_LAST"
    KEEP_ALL = "KEEP_ALL"
    SYSTEM_DEFAULT = "SYSTEM_DEFAULT"


class ReliabilityPolicy(str, Enum):
    RELIABLE = "RELIABLE"
    BEST_EFFORT = "BEST_EFFORT"
    SYSTEM_DEFAULT = "SYSTEM_DEFAULT"


class DurabilityPolicy(str, Enum):
    VOLATILE = "VOLATILE"
    TRANSIENT_LOCAL = "TRANSIENT_LOCAL"
    SYSTEM_DEFAULT = "SYSTEM_DEFAULT"


# Module-level names so `QoSConfig(durability=TRANSIENT_LOCAL)` reads as in ROS recipes.
KEEP_LAST, KEEP_ALL = HistoryPolicy.KEEP_LAST, HistoryPolicy.KEEP_ALL
RELIABLE, BEST_EFFORT = ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT
VOLATILE, TRANSIENT_LOCAL = DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL


def _history(value: object) -> HistoryPolicy:
    return enum_converter(HistoryPolicy)(value)


def _reliability(value: object) -> ReliabilityPolicy:
    return enum_converter(ReliabilityPolicy)(value)


def _durability(value: object) -> DurabilityPolicy:
    return enum_converter(DurabilityPolicy)(value)


@define(kw_only=True)
class QoSConfig(BaseAttrs):
    history: HistoryPolicy = field(default=HistoryPolicy.KEEP_LAST, converter=_history)
    queue_size: int = field(default=10, validator=in_range(min_value=1, max_value=10_000))
    reliability: ReliabilityPolicy = field(default=ReliabilityPolicy.RELIABLE, converter=_reliability)
    durability: DurabilityPolicy = field(default=DurabilityPolicy.VOLATILE, converter=_durability)

    @property
    def transient_local(self) -> bool:
        return self.durability == DurabilityPolicy.TRANSIENT_LOCAL
