"""std_msgs and builtin_interfaces."""
from __future__ import annotations

import time

import numpy as np

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type


@message_type("builtin_interfaces")
class Time(Message):
    sec: int = F.integer(bits=32)
    nanosec: int = F.integer(bits=32, signed=False)

    @classmethod
    def now(cls) -> Time:
        """The wall clock. A component stamps what it publishes with ``emos.core.clock.stamp()``
        instead, which follows the simulated clock when the run has one."""
        ns = time.time_ns()
        return cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    @classmethod
    def from_sec(cls, seconds: float) -> Time:
        ns = int(round(seconds * 1e9))
        return cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def to_sec(self) -> float:
        return self.sec + self.nanosec * 1e-9

    def to_nsec(self) -> int:
        return self.sec * 1_000_000_000 + self.nanosec


@message_type("builtin_interfaces")
class Duration(Message):
    sec: int = F.integer(bits=32)
    nanosec: int = F.integer(bits=32, signed=False)

    def to_sec(self) -> float:
        return self.sec + self.nanosec * 1e-9


@message_type("std_msgs")
class Header(Message):
    stamp: Time = F.message(Time)
    frame_id: str = F.string()


@message_type("std_msgs")
class Empty(Message):
    pass


@message_type("std_msgs")
class String(Message):
    data: str = F.string()


@message_type("std_msgs")
class Bool(Message):
    data: bool = F.boolean()


@message_type("std_msgs")
class Float32(Message):
    data: float = F.float32()


@message_type("std_msgs")
class Float64(Message):
    data: float = F.float64()


@message_type("std_msgs")
class Int32(Message):
    data: int = F.integer(bits=32)


@message_type("std_msgs")
class Int64(Message):
    data: int = F.integer(bits=64)


@message_type("std_msgs")
class UInt8(Message):
    data: int = F.integer(bits=8, signed=False)


@message_type("std_msgs")
class MultiArrayDimension(Message):
    label: str = F.string()
    size: int = F.integer(bits=32, signed=False)
    stride: int = F.integer(bits=32, signed=False)


@message_type("std_msgs")
class MultiArrayLayout(Message):
    dim: list[MultiArrayDimension] = F.message_list(MultiArrayDimension)
    data_offset: int = F.integer(bits=32, signed=False)


@message_type("std_msgs")
class Float32MultiArray(Message):
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: np.ndarray = F.array(dtype="float32")


@message_type("std_msgs")
class Float64MultiArray(Message):
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: np.ndarray = F.array(dtype="float64")


@message_type("std_msgs")
class Int32MultiArray(Message):
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: np.ndarray = F.array(dtype="int32")


@message_type("std_msgs")
class UInt8MultiArray(Message):
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: np.ndarray = F.bytes_array()


@message_type("rosgraph_msgs")
class Clock(Message):
    """Simulated time, published on ``/clock`` by the Simulator (see :mod:`emos.core.clock`)."""

    clock: Time = F.message(Time)


@message_type("sugar")
class LockstepAck(Message):
    """A lockstep consumer's answer to one ``/clock`` tick (on ``/clock_ack/<component>``, see
    :mod:`emos.core.clock`): the tick it handled, and the CPU seconds its steps took since its
    previous answer, which a Simulator that charges compute time turns into command latency."""

    clock: Time = F.message(Time)
    compute: float = F.float64()
