"""Spec for object detection / tracking models (MMDetection checkpoints on RoboML)."""
from __future__ import annotations

import attrs

from emos.config import validators as V

from .base import Model

__all__ = ["VisionModel"]


@attrs.define(kw_only=True)
class VisionModel(Model):
    """A detector, optionally with trackers (one per input image stream).

    ``tracking_distance_function`` is any ``scipy.spatial.distance.cdist`` metric name and
    ``tracking_distance_threshold`` the largest distance still counted as the same object.
    """

    checkpoint: str = attrs.field(default="dino-4scale_r50_8xb2-12e_coco", validator=attrs.validators.instance_of(str))
    cache_dir: str = attrs.field(default="mmdet", validator=attrs.validators.instance_of(str))
    setup_trackers: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    tracking_distance_function: str = attrs.field(default="euclidean", validator=attrs.validators.instance_of(str))
    tracking_distance_threshold: int = attrs.field(default=30, validator=V.int_at_least(1))
    deploy_tensorrt: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    _num_trackers: int = attrs.field(default=1, validator=V.int_at_least(1))

    INIT_FIELDS = (
        "checkpoint", "cache_dir", "setup_trackers", "tracking_distance_function",
        "tracking_distance_threshold", "deploy_tensorrt",
    )

    def get_init_params(self) -> dict:
        params = super().get_init_params()
        params["num_trackers"] = self._num_trackers
        return params
