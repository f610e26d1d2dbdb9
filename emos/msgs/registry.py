"""Message classes by name: ``"LaserScan"``, ``"sensor_msgs/msg/LaserScan"`` or the class itself.

Users register their own types with :func:`message_type`; the name then works everywhere a
built-in one does (topics, ``emos topic pub``, config files).
"""
from __future__ import annotations

import difflib
import hashlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import attrs

from emos.errors import EmosError
from emos.msgs.fields import bind_field_names

T = TypeVar("T")


class Message:
    """Base of every message class (attrs generates the real ``__init__`` per class).

    Type checkers see a keyword-only constructor; attribute types come from the annotations.
    """

    __slots__ = ()

    if TYPE_CHECKING:

        def __init__(self, **fields: Any) -> None: ...

_BY_NAME: dict[str, type] = {}  # short name and "pkg/msg/Name" -> class
_CANONICAL: dict[type, str] = {}  # class -> "pkg/msg/Name"


class UnknownMessageType(EmosError, LookupError):
    """A message type name that no registered class answers to."""


def message_type(package: str = "emos_msgs", name: str | None = None) -> Callable[[type[T]], type[T]]:
    """Class decorator: make an attrs message class and register it.

    ``@message_type("std_msgs")`` above a class body with fields from :mod:`emos.msgs.fields`.
    The class gets ``__slots__``, validation on construction and assignment, and a stable
    ``_emos_fingerprint`` of its layout that lets a subscriber refuse a publisher whose
    definition of the same name differs.
    """

    def wrap(cls: type[T]) -> type[T]:
        if not attrs.has(cls):
            cls = attrs.define(kw_only=True, eq=True)(cls)
        bind_field_names(cls)
        short = name or cls.__name__
        full = f"{package}/msg/{short}"
        # Two packages may both define a short name; it stays with the first, and the second is
        # reachable by its full name.
        _BY_NAME.setdefault(short, cls)
        _BY_NAME[full] = cls
        _CANONICAL[cls] = full
        layout = ";".join(f"{f.name}:{f.metadata.get('kind')}" for f in attrs.fields(cls))  # type: ignore[arg-type]
        cls._emos_fingerprint = hashlib.blake2b(f"{full}|{layout}".encode(), digest_size=8).hexdigest()  # type: ignore[union-attr]  # added here: no type can declare it
        return cls  # type: ignore[return-value]

    return wrap


def canonical_name(cls: type) -> str:
    try:
        return _CANONICAL[cls]
    except KeyError:
        raise UnknownMessageType(f"{cls!r} is not a registered message type; decorate it with @message_type") from None


def resolve(msg_type: Any) -> type:
    """The message class for a class, a short name or a full ``pkg/msg/Name``."""
    if isinstance(msg_type, type):
        canonical_name(msg_type)  # validates registration
        return msg_type
    if not isinstance(msg_type, str):
        raise UnknownMessageType(f"msg_type must be a message class or a type name, got {type(msg_type).__name__}")
    key = msg_type.strip()
    # Accept ROS-style spellings: "sensor_msgs/LaserScan", "sensor_msgs.msg.LaserScan".
    candidates = [key, key.replace(".msg.", "/msg/").replace(".", "/")]
    if key.count("/") == 1:
        pkg, short = key.split("/")
        candidates.append(f"{pkg}/msg/{short}")
    for cand in candidates:
        if cand in _BY_NAME:
            return _BY_NAME[cand]
    close = difflib.get_close_matches(key, sorted(_BY_NAME), n=5, cutoff=0.6)
    hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    raise UnknownMessageType(f"unknown message type {msg_type!r}{hint}")


def registered_types() -> dict[str, type]:
    """Every registered class by its canonical ``pkg/msg/Name``."""
    return {name: cls for cls, name in _CANONICAL.items()}
