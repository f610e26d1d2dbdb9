"""The configuration every component shares, and how it runs."""
from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from typing import Any, TypeVar

import attrs
from attrs import define, field

from emos.config import validators as base_validators


class ComponentRunType(str, Enum):
    """How a component's main step is driven."""

    TIMED = "Timed"  # every 1/loop_rate seconds
    EVENT = "Event"  # when a trigger topic receives a message
    SERVER = "Server"  # when a request arrives on its service
    ACTION_SERVER = "ActionServer"  # when a goal arrives on its action

    @classmethod
    def parse(cls, value: ComponentRunType | str) -> ComponentRunType:
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            for member in cls:
                if value.lower() in (member.value.lower(), member.name.lower()):
                    return member
        raise ValueError(f"run_type must be one of {[m.value for m in cls]}, got {value!r}")


_E = TypeVar("_E", bound=Enum)


def _enum_converter(enum_cls: type[_E]) -> Callable[[Any], _E]:
    def convert(value: Any) -> _E:
        if isinstance(value, enum_cls):
            return value
        if isinstance(value, str):
            for member in enum_cls:
                if value.lower() in (str(member.value).lower(), member.name.lower()):
                    return member
        raise ValueError(f"expected one of {[m.name for m in enum_cls]}, got {value!r}")

    return convert


enum_converter = _enum_converter


@define(kw_only=True)
class BaseAttrs:
    """attrs base with dict round-trips: the same metadata drives files, CLI and UI forms."""

    def asdict(self) -> dict[str, Any]:
        def ser(inst: Any, fld: attrs.Attribute[Any], value: Any) -> Any:
            if isinstance(value, Enum):
                return value.value if isinstance(value.value, (str, int, float)) else value.name
            if hasattr(value, "tolist"):
                return value.tolist()
            return value

        return attrs.asdict(self, value_serializer=ser)

    def update(self, **values: Any) -> None:
        """Set several fields; each is validated, and nothing changes if one fails."""
        known = {f.name for f in attrs.fields(type(self))}
        unknown = sorted(set(values) - known)
        if unknown:
            raise AttributeError(f"{type(self).__name__} has no parameter {', '.join(unknown)}; parameters are {', '.join(sorted(known))}")
        trial = attrs.evolve(self, **{k: v for k, v in values.items() if not k.startswith("_")})
        for name in values:
            object.__setattr__(self, name, getattr(trial, name))


@define(kw_only=True)
class BaseComponentConfig(BaseAttrs):
    """Parameters every component has. Extend it with ``@define(kw_only=True)`` subclasses."""

    loop_rate: float = field(default=100.0, validator=base_validators.in_range(min_value=1e-9, max_value=1e9))
    """Main-step frequency (Hz) for Timed components; also the idle heartbeat rate of the others."""

    fallback_rate: float = field(default=100.0, validator=base_validators.in_range(min_value=1e-9, max_value=1e9))
    """How often (Hz) fallback actions are retried while the component stays unhealthy."""

    heartbeat_rate: float = field(default=10.0, validator=base_validators.in_range(min_value=0.1, max_value=1e4))
    """Minimum status publication rate (Hz) when idle (Event, Server and ActionServer run types)."""

    visualization: bool = field(default=False)

    use_sim_time: bool = field(default=False)
    """Follow the Simulator's /clock: Timed steps run on simulated time and answer each tick
    (see :mod:`emos.core.clock`; list the component in the Simulator's ``lockstep_consumers``)."""
