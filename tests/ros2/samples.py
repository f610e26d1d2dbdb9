"""One sample of every message type shared with ROS 2, with no field left at its default.

Built from the ROS 2 type definitions (rosbags' typestore, the same ones the codec follows):
each base field gets a value derived from its position, each array its declared length (or
three elements), each nested message its own sample; then converted to our class. A round trip
keeps every field if the CDR bytes of what comes back equal those of what was sent.
"""
from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np

from emos.interop.ros2_cdr import codec_for

DISTRO = "jazzy"
_INT = {"int8": (-100, 100), "uint8": (0, 250), "byte": (0, 250), "char": (0, 250), "octet": (0, 250), "int16": (-30000, 30000),
        "uint16": (0, 60000), "int32": (-(2**30), 2**30), "uint32": (0, 2**31), "int64": (-(2**40), 2**40), "uint64": (0, 2**41)}
_DTYPE = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8, "float32": np.float32, "float64": np.float64,
          **{k: getattr(np, k) for k in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")}}


def _base(kind: str, k: int) -> Any:
    if kind == "string":
        return f"s{k}-é"
    if kind == "bool":
        return k % 2 == 1
    if kind in ("float32", "float64"):
        return 0.5 + k
    lo, hi = _INT[kind]
    return lo + (17 * k + 1) % (hi - lo)


def _value(store: Any, node: tuple, k: int) -> Any:
    nodetype, spec = node
    if nodetype == 1:
        return _base(spec[0], k)
    if nodetype == 2:
        return ros_sample(store, spec, k)
    sub, length = spec
    n = length or 3
    if sub[0] == 1 and sub[1][0] != "string":
        return np.array([_base(sub[1][0], k + i) for i in range(n)], dtype=_DTYPE[sub[1][0]])
    return [_value(store, sub, k + i) for i in range(n)]


def ros_sample(store: Any, ros_type: str, k: int = 1) -> Any:
    fields = store.fielddefs[ros_type][1]
    return store.types[ros_type](**{name: _value(store, node, k + 3 * i) for i, (name, node) in enumerate(fields)})


def shared_types_with_rclpy() -> dict[str, type]:
    """Shared types whose ROS 2 interface package is installed for rclpy (found, not imported)."""
    codec = codec_for(DISTRO)
    return {name: cls for name, cls in codec.shared_types().items() if importlib.util.find_spec(name.split("/")[0]) is not None}


def sample(ros_type: str) -> Any:
    codec = codec_for(DISTRO)
    cls = codec.class_for(ros_type)
    return codec.from_ros(cls, ros_sample(codec.store, ros_type))


def topic_of(ros_type: str) -> str:
    pkg, _, name = ros_type.split("/")
    return f"/rt/{pkg}_{name}"
