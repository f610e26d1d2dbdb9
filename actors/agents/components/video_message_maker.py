"""``VideoMessageMaker``: cuts a stream of camera frames into ``Video`` messages.

Without motion estimation every ``min_video_frames`` consecutive frames make one video. With
``motion_estimation_func`` ("frame_difference": mean absolute change of grey levels in [0, 1];
"optical_flow": mean Farneback flow magnitude in pixels) a video starts at the first frame that
moved more than ``threshold`` since the previous one and ends when the scene is still again:
it is published if it has at least ``min_video_frames`` frames (shorter ones are noise) and cut
at ``max_video_frames``.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs import sensor as S

from .base import ModelComponent, ModelComponentConfig
from .convert import ImageInputError, header_now, image_of

MOTION_FUNCTIONS = (None, "frame_difference", "optical_flow")


@define(kw_only=True)
class VideoMessageMakerConfig(ModelComponentConfig):
    min_video_frames: int = field(default=15, validator=V.in_range(1, 100_000))
    max_video_frames: int = field(default=600, validator=V.in_range(1, 100_000))
    motion_estimation_func: str | None = field(default=None, validator=V.in_(MOTION_FUNCTIONS))
    threshold: float = field(default=0.3, validator=V.in_range(0.0, 1e6))
    flow_kwargs: dict = field(factory=lambda: {"pyr_scale": 0.5, "levels": 3, "winsize": 15, "iterations": 3,
                                               "poly_n": 5, "poly_sigma": 1.1, "flags": 0})
    max_pending: int = field(default=64, validator=V.in_range(1, 100_000))

    def __attrs_post_init__(self) -> None:
        if self.min_video_frames > self.max_video_frames:
            raise ValueError(f"VideoMessageMakerConfig: min_video_frames ({self.min_video_frames}) > max_video_frames ({self.max_video_frames})")


def motion(previous: np.ndarray, current: np.ndarray, method: str, flow_kwargs: dict) -> float:
    """How much ``current`` moved since ``previous`` (grey uint8 frames of one size)."""
    if method == "frame_difference":
        return float(np.mean(np.abs(current.astype(np.int16) - previous.astype(np.int16)))) / 255.0
    import cv2

    # flow=None: cv2 allocates the output; opencv's stubs leave None out of that parameter's type.
    flow = cv2.calcOpticalFlowFarneback(previous, current, None, **flow_kwargs)  # type: ignore[call-overload]
    return float(np.mean(np.linalg.norm(flow, axis=2)))


class VideoMessageMaker(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = VideoMessageMakerConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (S.Image, S.CompressedImage)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = (I.Video,)
    MODEL_OPTIONAL: ClassVar[bool] = True

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic], config: VideoMessageMakerConfig | None = None,
                 trigger: Any = None, component_name: str, **kwargs: Any) -> None:
        inputs = list(inputs)
        if len(inputs) != 1 or not outputs:
            raise ValueError(f"component {component_name!r}: VideoMessageMaker takes one image input and a Video output")
        super().__init__(inputs=inputs, outputs=outputs, config=config, trigger=trigger or inputs[0],
                         component_name=component_name, **kwargs)
        self.config: VideoMessageMakerConfig
        self._frames: list[Any] = []
        self._previous: np.ndarray | None = None
        self.videos = 0

    def activate_resources(self) -> None:
        super().activate_resources()
        self._frames, self._previous = [], None

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        msg = inputs.get(self.in_topics[0].name)
        if msg is None:
            return None
        return lambda: self._add(msg)

    def _add(self, msg: Any) -> None:
        cfg = self.config
        try:
            grey = image_of(msg, self.in_topics[0].name).mean(axis=2).astype(np.uint8)
        except ImageInputError as exc:
            self.health_status.set_fail_system(topic_names=[self.in_topics[0].name], message=str(exc))
            self._errors("image", "[%s] %s", self.component_name, exc)
            return
        if cfg.motion_estimation_func is None:
            self._frames.append(msg)
            if len(self._frames) >= cfg.min_video_frames:
                self._emit()
        else:
            previous, self._previous = self._previous, grey
            moving = previous is not None and previous.shape == grey.shape and \
                motion(previous, grey, cfg.motion_estimation_func, cfg.flow_kwargs) > cfg.threshold
            if moving:
                self._frames.append(msg)
                if len(self._frames) >= cfg.max_video_frames:
                    self._emit()
            elif self._frames:
                if len(self._frames) >= cfg.min_video_frames:
                    self._emit()
                else:
                    self._frames = []
        self.health_status.set_healthy()

    def _emit(self) -> None:
        frames, self._frames = self._frames, []
        # Held frames beyond the subscriber's two loans are copies, so a long video never
        # stalls the camera's ring; publishing copies them once more into the video's ring.
        images = [f for f in frames if isinstance(f, S.Image)]
        compressed = [f for f in frames if isinstance(f, S.CompressedImage)]
        video = I.Video(header=header_now(), frames=images, compressed_frames=compressed)
        for topic in self.out_topics:
            self.publish_output(topic, video)
        self.videos += 1
