"""Weights of the trajectory cost terms (spec names, defaults and ranges)."""
from __future__ import annotations

import attrs

from emos.config import validators as V

__all__ = ["TrajectoryCostsWeights"]


@attrs.define
class TrajectoryCostsWeights:
    """Weights ``w_i`` of ``J = sum(w_i * C_i)``. A weight of 0 skips that kernel entirely."""

    reference_path_distance_weight: float = attrs.field(default=3.0, converter=float, validator=V.number(ge=0.0, le=1e3, what="a weight"), on_setattr=attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate))
    goal_distance_weight: float = attrs.field(default=3.0, converter=float, validator=V.number(ge=0.0, le=1e3, what="a weight"), on_setattr=attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate))
    obstacles_distance_weight: float = attrs.field(default=1.0, converter=float, validator=V.number(ge=0.0, le=1e3, what="a weight"), on_setattr=attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate))
    smoothness_weight: float = attrs.field(default=0.0, converter=float, validator=V.number(ge=0.0, le=1e3, what="a weight"), on_setattr=attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate))
    jerk_weight: float = attrs.field(default=0.0, converter=float, validator=V.number(ge=0.0, le=1e3, what="a weight"), on_setattr=attrs.setters.pipe(attrs.setters.convert, attrs.setters.validate))
