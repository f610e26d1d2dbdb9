"""Validators for attrs config fields (``base_validators.in_range`` etc., as in the spec)."""
from __future__ import annotations

from typing import Any, Callable, Iterable

import attrs


def in_range(min_value: float, max_value: float) -> Callable[[Any, attrs.Attribute, Any], None]:
    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"{type(instance).__name__}.{attribute.name} expects a number in [{min_value}, {max_value}], got {value!r}")
        if not min_value <= value <= max_value:
            raise ValueError(f"{type(instance).__name__}.{attribute.name} must be in [{min_value}, {max_value}], got {value!r}")

    check.emos_range = (min_value, max_value)  # type: ignore[attr-defined]  # read by UI forms
    return check


def in_(options: Iterable[Any]) -> Callable[[Any, attrs.Attribute, Any], None]:
    allowed = list(options)

    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        if value not in allowed:
            raise ValueError(f"{type(instance).__name__}.{attribute.name} must be one of {allowed}, got {value!r}")

    check.emos_choices = allowed  # type: ignore[attr-defined]  # read by UI forms
    return check


def positive(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"{type(instance).__name__}.{attribute.name} must be a positive number, got {value!r}")


def list_contained_in(options: Iterable[Any]) -> Callable[[Any, attrs.Attribute, Any], None]:
    allowed = list(options)

    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        bad = [v for v in value if v not in allowed]
        if bad:
            raise ValueError(f"{type(instance).__name__}.{attribute.name}: {bad} not among {allowed}")

    return check
