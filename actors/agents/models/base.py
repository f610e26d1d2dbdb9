"""Base of every model specification, plus the registry that rebuilds specs from dicts.

A model spec says *what* to load (checkpoint, quantization, voice...) independently of *where*
it is served; clients turn it into the init payload their platform expects. Specs are attrs
classes validated on construction and on every attribute set, so a typo fails in the recipe
line that made it, not minutes later on the robot.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import attrs

from emos.config import validators as V

__all__ = ["Model", "model_from_dict", "MODEL_TYPES", "non_empty_str", "optional_positive", "options_validator"]

# Kept under their old names for the model specs that import them from here.
non_empty_str = V.non_empty_str
optional_positive = V.positive_or_none

#: class name -> class, filled by Model subclasses; used to rebuild specs in other processes.
MODEL_TYPES: dict[str, type[Model]] = {}


def options_validator(allowed: Mapping[str, type | tuple[type, ...]]):
    """Validator for an ``options`` dict: only known keys, each with its expected type."""

    def check(instance: Any, attribute: attrs.Attribute, value: Any) -> None:
        if value is None:
            return
        name = f"{type(instance).__name__}.{attribute.name}"
        if not isinstance(value, dict):
            raise TypeError(f"{name}: expected a dict or None, got {type(value).__name__}")
        for key, val in value.items():
            if key not in allowed:
                raise ValueError(f"{name}: unknown option {key!r}; expected one of {sorted(allowed)}")
            expected = allowed[key]
            if key == "stop":
                if not (isinstance(val, list) and all(isinstance(s, str) for s in val)):
                    raise TypeError(f"{name}[{key!r}]: expected a list of strings, got {val!r}")
                continue
            # ints are fine where floats are expected (temperature=1), bools never are numbers.
            if expected is float:
                expected = (int, float)
            if isinstance(val, bool) and bool not in (expected if isinstance(expected, tuple) else (expected,)):
                raise TypeError(f"{name}[{key!r}]: expected {_type_name(allowed[key])}, got bool")
            if not isinstance(val, expected):
                raise TypeError(f"{name}[{key!r}]: expected {_type_name(allowed[key])}, got {type(val).__name__}")

    return check


def _type_name(t: type | tuple[type, ...]) -> str:
    return " or ".join(x.__name__ for x in t) if isinstance(t, tuple) else t.__name__


@attrs.define(kw_only=True)
class Model:
    """Common fields: a free ``name``, the ``checkpoint`` to load and an ``init_timeout`` (s)."""

    name: str = attrs.field(validator=non_empty_str)
    checkpoint: str = attrs.field(default="", validator=attrs.validators.instance_of(str))
    init_timeout: int | None = attrs.field(default=None, validator=optional_positive)

    #: fields sent to the serving platform to initialize the model (subclasses extend it).
    INIT_FIELDS: ClassVar[tuple[str, ...]] = ("checkpoint",)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        MODEL_TYPES[cls.__name__] = cls

    @property
    def model_type(self) -> str:
        return type(self).__name__

    def get_init_params(self) -> dict[str, Any]:
        """The payload a serving platform needs to initialize this model."""
        return {f: getattr(self, f) for f in self.INIT_FIELDS}

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON/msgpack-able form; :func:`model_from_dict` rebuilds the spec."""
        data = attrs.asdict(self, recurse=True, filter=lambda a, _v: a.init)
        # attrs strips the leading underscore of private fields in __init__ arguments.
        data = {k.lstrip("_"): v for k, v in data.items()}
        return {"model_type": self.model_type, **data}


def model_from_dict(data: dict[str, Any]) -> Model:
    """Rebuild a model spec from :meth:`Model.to_dict` output."""
    if not isinstance(data, dict) or "model_type" not in data:
        raise ValueError(f"model spec: expected a dict with a 'model_type' key, got {data!r}")
    fields = dict(data)
    kind = fields.pop("model_type")
    cls = MODEL_TYPES.get(kind)
    if cls is None:
        raise ValueError(f"model spec: unknown model_type {kind!r}; expected one of {sorted(MODEL_TYPES)}")
    return cls(**fields)
