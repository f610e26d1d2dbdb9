"""std_msgs and builtin_interfaces."""
from __future__ import annotations

import time

from emos.msgs import fields as F
from emos.msgs.registry import message_type


@message_type("builtin_interfaces")
class Time:
    sec: int = F.integer(bits=32)
    nanosec: int = F.integer(bits=32, signed=False)

    @classmethod
    def now(cls) -> "Time":
        ns = time.time_ns()
        return cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    @classmethod
    def from_sec(cls, seconds: float) -> "Time":
        ns = int(round(seconds * 1e9))
        return cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def to_sec(self) -> float:
        return self.sec + self.nanosec * 1e-9

    def to_nsec(self) -> int:
        return self.sec * 1_000_000_000 + self.nanosec


@message_type("builtin_interfaces")
class Duration:
    sec: int = F.integer(bits=32)
    nanosec: int = F.integer(bits=32, signed=False)

    def to_sec(self) -> float:
        return self.sec + self.nanosec * 1e-9


@message_type("std_msgs")
class Header:
    stamp: Time = F.message(Time)
    frame_id: str = F.string()


@message_type("std_msgs")
class Empty:
    pass


@message_type("std_msgs")
class String:
    data: str = F.string()


@message_type("std_msgs")
class Bool:
    data: bool = F.boolean()


@message_type("std_msgs")
class Float32:
    data: float = F.float32()


@message_type("std_msgs")
class Float64:
    data: float = F.float64()


@message_type("std_msgs")
class Int32:
    data: int = F.integer(bits=32)


@message_type("std_msgs")
class Int64:
    data: int = F.integer(bits=64)


@message_type("std_msgs")
class UInt8:
    data: int = F.integer(bits=8, signed=False)


@message_type("std_msgs")
class MultiArrayDimension:
    label: str = F.string()
    size: int = F.integer(bits=32, signed=False)
    stride: int = F.integer(bits=32, signed=False)


@message_type("std_msgs")
class MultiArrayLayout:
    dim: list = F.message_list(MultiArrayDimension)
    data_offset: int = F.integer(bits=32, signed=False)


@message_type("std_msgs")
class Float32MultiArray:
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: object = F.array(dtype="float32")


@message_type("std_msgs")
class Float64MultiArray:
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: object = F.array(dtype="float64")


@message_type("std_msgs")
class Int32MultiArray:
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: object = F.array(dtype="int32")


@message_type("std_msgs")
class UInt8MultiArray:
    layout: MultiArrayLayout = F.message(MultiArrayLayout)
    data: object = F.bytes_array()
