"""Field constructors for message classes.

Every message field is declared through one of these helpers. Each attaches a ``kind`` to the
attrs metadata, which the codec reads to encode the field without inspecting values at run
time, and a converter that checks the value on construction *and* on assignment (attrs runs
converters on ``setattr`` for ``@define`` classes), so a wrong type fails where it was written,
with the message class and field named.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import attrs
import numpy as np

from emos.errors import EmosError

# Field kinds understood by the codec.
PRIMITIVE = "primitive"  # bool, int, float, str: msgpack-native
ARRAY = "array"  # numpy array: shipped as raw bytes with dtype and shape
MESSAGE = "message"  # nested message
MESSAGE_LIST = "message_list"  # list of nested messages
STR_LIST = "str_list"  # list of strings
OPTIONAL_MESSAGE = "optional_message"  # nested message or None


class FieldTypeError(EmosError, TypeError):
    """A value of the wrong type was given for a message field."""


def _where(owner: str, name: str) -> str:
    return f"{owner}.{name}" if owner else name


def _bad(owner: str, name: str, expected: str, value: Any) -> FieldTypeError:
    shown = repr(value)
    if len(shown) > 60:
        shown = shown[:57] + "..."
    return FieldTypeError(f"{_where(owner, name)} expects {expected}, got {type(value).__name__} {shown}")


class _Checked:
    """A converter that knows its field's name, filled in by :func:`bind_field_names`."""

    def __init__(self, expected: str, convert: Callable[[Any], Any]):
        self.expected = expected
        self.convert = convert
        self.owner = ""
        self.name = ""

    def __call__(self, value: Any) -> Any:
        try:
            return self.convert(value)
        except FieldTypeError:
            raise
        except (TypeError, ValueError, OverflowError) as exc:
            raise _bad(self.owner, self.name, self.expected, value) from exc


def _float(value: Any) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError
    return float(value)


def _int_in(lo: int, hi: int) -> Callable[[Any], int]:
    def convert(value: Any) -> int:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            # Accept integral floats (1.0) as ROS's Python API does not, but YAML often produces them.
            if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
                value = int(value)
            else:
                raise TypeError
        number = int(value)
        if not lo <= number <= hi:
            raise ValueError
        return number

    return convert


def _bool(value: Any) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise TypeError


def _str(value: Any) -> str:
    if isinstance(value, str):
        return value
    raise TypeError


def float64(default: float = 0.0) -> Any:
    return attrs.field(default=default, converter=_Checked("a float", _float), metadata={"kind": PRIMITIVE})


float32 = float64  # Python floats are doubles; the distinction matters only for arrays.


def integer(default: int = 0, bits: int = 32, signed: bool = True) -> Any:
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    kind = f"an int{'' if signed else ' (unsigned)'} in [{lo}, {hi}]"
    return attrs.field(default=default, converter=_Checked(kind, _int_in(lo, hi)), metadata={"kind": PRIMITIVE})


def boolean(default: bool = False) -> Any:
    return attrs.field(default=default, converter=_Checked("a bool", _bool), metadata={"kind": PRIMITIVE})


def string(default: str = "") -> Any:
    return attrs.field(default=default, converter=_Checked("a str", _str), metadata={"kind": PRIMITIVE})


def array(dtype: Any = None, ndim: int | None = None, shape: tuple[int, ...] | None = None) -> Any:
    """A numpy array field. ``dtype=None`` keeps whatever dtype the sender used.

    ``shape`` fixes the size (ROS fixed arrays such as ``CameraInfo.k[9]``); ``ndim`` fixes only
    the rank (``-1`` entries in ``shape`` are free).
    """
    target = np.dtype(dtype) if dtype is not None else None
    expected = "an array" + (f" of {target}" if target is not None else "") + (f" with shape {shape}" if shape else "")
    # An empty list (``[]`` from JSON, YAML or the CLI) has no shape of its own: it is the empty
    # array of any shape with a free (-1) dimension, e.g. (0, 4) for boxes of shape (-1, 4).
    empty = tuple(0 if s == -1 else s for s in shape) if shape is not None and -1 in shape else None

    def convert(value: Any) -> np.ndarray:
        if isinstance(value, (str, bytes)) and not isinstance(value, (bytes, bytearray)):
            raise TypeError
        arr = np.asarray(value, dtype=target) if target is not None else np.asarray(value)
        if arr.dtype == object:
            raise TypeError
        if empty is not None and arr.shape == (0,) and len(empty) != 1:
            arr = arr.reshape(empty)
        if ndim is not None and arr.ndim != ndim:
            if arr.size == 0:
                arr = arr.reshape((0,) * ndim)
            else:
                raise ValueError
        if shape is not None:
            if len(shape) != arr.ndim and not (arr.ndim == 1 and len(shape) == 1):
                raise ValueError
            if any(want not in (-1, got) for want, got in zip(shape, arr.shape)):
                raise ValueError
        return arr

    if shape is not None:
        default = attrs.Factory(lambda: np.zeros([max(s, 0) for s in shape], dtype=target or np.float64))
    else:
        default = attrs.Factory(lambda: np.zeros((0,) * (ndim or 1), dtype=target or np.float64))
    return attrs.field(default=default, converter=_Checked(expected, convert), metadata={"kind": ARRAY}, eq=False)


def bytes_array() -> Any:
    """Raw bytes as a uint8 array (``Image.data``, ``CompressedImage.data``, ``Audio.data``)."""

    def convert(value: Any) -> np.ndarray:
        if isinstance(value, (bytes, bytearray, memoryview)):
            return np.frombuffer(value, dtype=np.uint8)
        arr = np.asarray(value)
        if arr.dtype != np.uint8:
            if arr.size and not np.issubdtype(arr.dtype, np.integer):
                raise TypeError
            arr = arr.astype(np.uint8)
        return arr

    return attrs.field(
        default=attrs.Factory(lambda: np.zeros(0, dtype=np.uint8)),
        converter=_Checked("bytes or a uint8 array", convert),
        metadata={"kind": ARRAY},
        eq=False,
    )


def message(cls: Any) -> Any:
    """A nested message; ``cls`` may be a class or a zero-argument callable returning it."""

    def resolve() -> type:
        return cls if isinstance(cls, type) else cls()

    def convert(value: Any) -> Any:
        target = resolve()
        if isinstance(value, target):
            return value
        if isinstance(value, dict):
            return target(**value)
        raise TypeError

    checked = _Checked("a message", convert)
    return attrs.field(
        factory=lambda: resolve()(), converter=checked, metadata={"kind": MESSAGE, "cls": resolve}
    )


def optional_message(cls: Any) -> Any:
    def resolve() -> type:
        return cls if isinstance(cls, type) else cls()

    def convert(value: Any) -> Any:
        if value is None or isinstance(value, resolve()):
            return value
        raise TypeError

    return attrs.field(
        default=None, converter=_Checked("a message or None", convert), metadata={"kind": OPTIONAL_MESSAGE, "cls": resolve}
    )


def message_list(cls: Any) -> Any:
    def resolve() -> type:
        return cls if isinstance(cls, type) else cls()

    def convert(value: Any) -> list[Any]:
        target = resolve()
        if isinstance(value, (str, bytes)):
            raise TypeError
        items = list(value)
        for item in items:
            if not isinstance(item, target):
                raise TypeError
        return items

    return attrs.field(
        factory=list, converter=_Checked("a list of messages", convert), metadata={"kind": MESSAGE_LIST, "cls": resolve}
    )


def string_list() -> Any:
    def convert(value: Any) -> list[str]:
        if isinstance(value, (str, bytes)):
            raise TypeError
        items = list(value)
        if not all(isinstance(v, str) for v in items):
            raise TypeError
        return items

    return attrs.field(factory=list, converter=_Checked("a list of str", convert), metadata={"kind": STR_LIST})


def bind_field_names(cls: type) -> type:
    """Tell each field's converter its owner and name, for error messages."""
    for fld in attrs.fields(cls):
        conv = fld.converter
        # attrs may wrap converters; reach the _Checked instance where it is exposed.
        target = getattr(conv, "converter", conv)
        if isinstance(target, _Checked):
            target.owner = cls.__name__
            target.name = fld.name
    return cls
