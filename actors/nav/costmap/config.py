"""attrs configs of the costmap and the smoother, with Nav2's parameter names."""
from __future__ import annotations

from typing import Any

from attrs import define, field

from emos.config.validators import in_range

__all__ = ["CostmapConfig", "SmootherConfig", "mask_path"]


def mask_path(kind: str) -> Any:
    """attrs validator of a filter mask path ('': none): loads the mask, so a bad one is refused
    where it is set, naming the file and the bad value."""
    def check(instance: Any, attribute: Any, value: Any) -> None:
        if not isinstance(value, str):
            raise TypeError(f"{attribute.name}: expected a mask YAML path (str), got {type(value).__name__}")
        if value:  # refused at definition: a bad mask names its file and the bad value
            from .filters import load_filter_mask
            load_filter_mask(value, kind)
    return check


@define(kw_only=True)
class CostmapConfig:
    """``enabled``: build the layered costmap (static + inflation + filters) and plan on it.
    ``inflation_radius`` (m), ``cost_scaling_factor`` (1/m), ``inscribed_radius`` (m, 0: the
    robot footprint's inscribed radius), ``inflate_unknown``: the inflation layer.
    ``lethal_cost_threshold``, ``track_unknown_space``: the static layer. ``keepout_mask``,
    ``speed_mask``: filter mask YAML files ('' for none), loaded and checked when set."""

    enabled: bool = field(default=False)
    inflation_radius: float = field(default=0.55, validator=in_range(min_value=0.0, max_value=100.0))
    cost_scaling_factor: float = field(default=10.0, validator=in_range(min_value=0.0, max_value=1e4))
    inscribed_radius: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=100.0))
    inflate_unknown: bool = field(default=False)
    lethal_cost_threshold: int = field(default=100, validator=in_range(min_value=0, max_value=100))
    track_unknown_space: bool = field(default=True)
    keepout_mask: str = field(default="", validator=mask_path("keepout"))
    speed_mask: str = field(default="", validator=mask_path("speed"))


@define(kw_only=True)
class SmootherConfig:
    """Nav2's simple smoother: ``tolerance`` (stop when a sweep moves the path less),
    ``max_its``, ``w_data`` (pull to the original), ``w_smooth`` (pull to the neighbours'
    mean), ``do_refinement`` / ``refinement_num`` (smooth the smoothed path again)."""

    enabled: bool = field(default=False)
    tolerance: float = field(default=1e-10, validator=in_range(min_value=0.0, max_value=1.0))
    max_its: int = field(default=1000, validator=in_range(min_value=1, max_value=1_000_000))
    w_data: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=1.0))
    w_smooth: float = field(default=0.3, validator=in_range(min_value=0.0, max_value=0.5))
    do_refinement: bool = field(default=True)
    refinement_num: int = field(default=2, validator=in_range(min_value=1, max_value=100))
