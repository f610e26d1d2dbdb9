"""Validators for attrs config fields (``base_validators.in_range`` etc., as in the spec).

The one home for field checks: configs across EMOS use these instead of local copies. Each
message names ``Class.field``, says what was expected and shows the value given. ``in_range``
and ``in_`` also tell the UI forms the range or the choices; the others do not, so a form is
unchanged by which of them a field uses.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import attrs

Validator = Callable[[Any, "attrs.Attribute[Any]", Any], None]


def _field(instance: Any, attribute: Any) -> str:
    """``Class.field`` as the caller spells it (the init argument of a private attribute)."""
    name = getattr(attribute, "alias", None) or attribute.name
    return f"{type(instance).__name__}.{name}"


def in_range(min_value: float, max_value: float) -> Validator:
    def check(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"{_field(instance, attribute)} expects a number in [{min_value}, {max_value}], got {value!r}")
        if not min_value <= value <= max_value:
            raise ValueError(f"{_field(instance, attribute)} must be in [{min_value}, {max_value}], got {value!r}")

    check.emos_range = (min_value, max_value)  # type: ignore[attr-defined]  # read by UI forms
    return check


def in_(options: Iterable[Any]) -> Validator:
    allowed = list(options)

    def check(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
        if value not in allowed:
            raise ValueError(f"{_field(instance, attribute)} must be one of {allowed}, got {value!r}")

    check.emos_choices = allowed  # type: ignore[attr-defined]  # read by UI forms
    return check


def positive(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"{_field(instance, attribute)} must be a positive number, got {value!r}")


def list_contained_in(options: Iterable[Any]) -> Validator:
    allowed = list(options)

    def check(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
        bad = [v for v in value if v not in allowed]
        if bad:
            raise ValueError(f"{_field(instance, attribute)}: {bad} not among {allowed}")

    return check


def _bounds(gt: float | None, ge: float | None, lt: float | None, le: float | None) -> str:
    low = f"({gt}" if gt is not None else f"[{ge}" if ge is not None else None
    high = f"{lt})" if lt is not None else f"{le}]" if le is not None else None
    if low and high:
        return f" in {low}, {high}"
    if low:
        return f" > {gt}" if gt is not None else f" >= {ge}"
    if high:
        return f" < {lt}" if lt is not None else f" <= {le}"
    return ""


def number(*, gt: float | None = None, ge: float | None = None, lt: float | None = None, le: float | None = None,
           integer: bool = False, finite: bool = False, allow_none: bool = False, what: str | None = None) -> Validator:
    """A number (an ``int`` with ``integer``; never a bool) within the given bounds.

    ``finite`` also refuses inf (NaN never passes a bound); ``allow_none`` lets None through;
    ``what`` names the quantity in the message ("a rate in Hz", "a number of seconds"). Refusals
    are ValueError: "SimulatorConfig.physics_rate must be a rate in Hz > 0, got 0".
    """
    kind = what or ("an integer" if integer else "a finite number" if finite else "a number")
    expected = kind + _bounds(gt, ge, lt, le) + (" or None" if allow_none else "")
    types: type | tuple[type, ...] = int if integer else (int, float)

    def check(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
        if value is None and allow_none:
            return
        ok = isinstance(value, types) and not isinstance(value, bool)
        if ok and finite and isinstance(value, float):
            ok = math.isfinite(value)
        if ok:
            ok = ((gt is None or value > gt) and (ge is None or value >= ge)
                  and (lt is None or value < lt) and (le is None or value <= le))
        if not ok:
            raise ValueError(f"{_field(instance, attribute)} must be {expected}, got {value!r}")

    return check


#: A finite number > 0 (a length, a period, a gain).
finite_positive = number(gt=0, finite=True)
#: A finite number >= 0 (a margin, a noise level, a hold time).
finite_non_negative = number(ge=0, finite=True)
#: A number > 0, or None for "not set" (an optional timeout or distance).
positive_or_none = number(gt=0, allow_none=True)


def int_at_least(low: int) -> Validator:
    """An ``int`` (not a bool) >= ``low``: a count, a size in pixels, a seed."""
    return number(ge=low, integer=True)


def non_empty_str(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
    """A string with something besides white space in it (a name, a host, a path)."""
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{_field(instance, attribute)} must be a non-empty string, got {value!r}")


def instance_of(cls: type) -> Validator:
    """An instance of ``cls``; refusals are TypeError naming the field and the class expected."""

    def check(instance: Any, attribute: attrs.Attribute[Any], value: Any) -> None:
        if not isinstance(value, cls):
            raise TypeError(f"{_field(instance, attribute)} must be a {cls.__name__}, got {type(value).__name__} {value!r}")

    return check
