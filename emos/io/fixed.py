"""``FixedInput``: an input that always reads the same value, with no publisher behind it.

A timed component that asks itself the same question every few seconds takes the question as a
FixedInput. The node never subscribes to it; reading it yields ``fixed`` as a message of
``msg_type`` (a str becomes a ``String``, an array an ``Image`` or a ``Float64MultiArray``...).
"""
from __future__ import annotations

from typing import Any

from attrs import define, field

from emos.io.topic import Topic


def _to_message(msg_type: type, value: Any) -> Any:
    if isinstance(value, msg_type):
        return value
    from emos.msgs import sensor, std

    if msg_type in (std.String,) and isinstance(value, str):
        return std.String(data=value)
    if msg_type is sensor.Image:
        import numpy as np

        arr = np.asarray(value)
        return sensor.Image.from_numpy(arr, "mono8" if arr.ndim == 2 else "rgb8")
    if hasattr(msg_type, "data"):
        try:
            return msg_type(data=value)
        except Exception as exc:
            raise TypeError(f"FixedInput: cannot make a {msg_type.__name__} from {type(value).__name__}: {exc}") from None
    raise TypeError(f"FixedInput: cannot make a {msg_type.__name__} from {type(value).__name__}; pass a {msg_type.__name__} message")


@define(kw_only=True, eq=False)
class FixedInput(Topic):
    """``FixedInput(name="question", msg_type="String", fixed="What room is this?")``."""

    fixed: Any = field()
    message: Any = field(init=False, default=None)

    def __attrs_post_init__(self) -> None:
        if self.fixed is None or (isinstance(self.fixed, str) and not self.fixed.strip()):
            raise ValueError(f"FixedInput {self.name!r}: fixed must be a non-empty value")
        self.message = _to_message(self.msg_type, self.fixed)

    def __repr__(self) -> str:
        return f"FixedInput(name={self.name!r}, msg_type={self.type_name!r}, fixed={self.fixed!r})"
