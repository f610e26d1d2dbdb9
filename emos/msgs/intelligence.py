"""EmbodiedAgents messages: streamed text, video, detections, points of interest, trackings."""
from __future__ import annotations

import numpy as np

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type
from emos.msgs.sensor import CompressedImage, Image
from emos.msgs.std import Header


@message_type("automatika_embodied_agents")
class StreamingString(Message):
    """One chunk of a streamed reply; ``done`` marks the last one."""

    stream: bool = F.boolean()
    done: bool = F.boolean(True)
    data: str = F.string()


@message_type("automatika_embodied_agents")
class Video(Message):
    header: Header = F.message(Header)
    frames: list[Image] = F.message_list(Image)
    compressed_frames: list[CompressedImage] = F.message_list(CompressedImage)


@message_type("automatika_embodied_agents")
class Detections(Message):
    """2D detections in one image: ``boxes`` is (N, 4) as x1, y1, x2, y2 in pixels."""

    header: Header = F.message(Header)
    scores: np.ndarray = F.array(dtype="float64", ndim=1)
    labels: list[str] = F.string_list()
    boxes: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 4))
    image: Image | None = F.optional_message(Image)

    def __attrs_post_init__(self) -> None:
        n = len(self.labels)
        if len(self.scores) != n or len(self.boxes) != n:
            raise ValueError(f"Detections needs as many scores and boxes as labels: {len(self.scores)} scores, {len(self.boxes)} boxes, {n} labels")


@message_type("automatika_embodied_agents")
class DetectionsMultiSource(Message):
    header: Header = F.message(Header)
    detections: list[Detections] = F.message_list(Detections)


@message_type("automatika_embodied_agents")
class PointsOfInterest(Message):
    """Pixel coordinates of interest in an image: ``points`` is (N, 2) as x, y."""

    header: Header = F.message(Header)
    points: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 2))
    image: Image | None = F.optional_message(Image)


@message_type("automatika_embodied_agents")
class Trackings(Message):
    """Tracked objects: ids, labels, boxes (N, 4), centroids (N, 2) and pixel velocities (N, 2)."""

    header: Header = F.message(Header)
    ids: np.ndarray = F.array(dtype="int64", ndim=1)
    labels: list[str] = F.string_list()
    boxes: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 4))
    centroids: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 2))
    estimated_velocities: np.ndarray = F.array(dtype="float64", ndim=2, shape=(-1, 2))
    image: Image | None = F.optional_message(Image)


@message_type("automatika_embodied_agents")
class TrackingsMultiSource(Message):
    header: Header = F.message(Header)
    trackings: list[Trackings] = F.message_list(Trackings)
