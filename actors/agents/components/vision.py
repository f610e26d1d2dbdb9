"""``Vision``: object detection (and tracking) on camera frames.

Detections come from the model client's detector (e.g. a ``VisionModel`` on RoboML) or, with
``enable_local_classifier=True``, from the on-board OpenCV detectors (people and faces) that run
inside the component's process. Frames are taken latest-first: while a frame is being
processed only the newest one waits, older ones are dropped and counted, so a slow detector
never builds a backlog. Trackings outputs get ids and pixel velocities from a centroid tracker.

An ``RGBD`` input is detected on its colour image and its depth image travels with the
detections (``Detections.image``), so a depth follower needs no second, unsynchronised
subscription. With ``include_image`` the frame travels with them (a compressed frame decoded
to rgb8), so consumers know the image size and can read the pixels.

With ``enable_visualization`` (the spec's debugging pop-up window) the frame with its boxes and
labels drawn on it is published as an ``Image`` on ``<component_name>/visualization``
(``vision.visualization_topic``) for the web UI, Foxglove or ``emos topic echo``: a robot is
usually headless, so no window is opened (see ``vision_viz``).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.core import clock
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs.control import RGBD
from emos.msgs.sensor import Image

from ..logic.tracking import CentroidTracker
from ..types import Detection2D, DetectionRequest
from .base import ModelComponent, ModelComponentConfig
from .convert import IMAGE_TYPES, ImageInputError, header_now, image_of
from .vision_viz import annotate, tile

DETECTION_OUTPUTS = (I.Detections, I.DetectionsMultiSource, I.Trackings, I.TrackingsMultiSource)


@define(kw_only=True)
class VisionConfig(ModelComponentConfig):
    threshold: float = field(default=0.5, validator=V.in_range(0.0, 1.0))
    labels_to_track: list[str] | None = field(default=None)
    enable_local_classifier: bool = field(default=False)
    #: the local classifier sees frames scaled to fit in input_width x input_height (boxes are
    #: mapped back to the original pixels): the OpenCV detectors cost ~4x less at 320x240 than
    #: at 640x480 on a CPU
    input_width: int = field(default=320, validator=V.in_range(32, 8192))
    input_height: int = field(default=240, validator=V.in_range(32, 8192))
    tracking_distance_threshold: float = field(default=30.0, validator=V.in_range(1e-3, 1e6))
    tracking_max_age: float = field(default=1.0, validator=V.in_range(1e-3, 1e6))
    #: attach the frame to each Detections/Trackings message (downstream consumers that need
    #: the pixels, e.g. visual trackers, then need no second subscription)
    include_image: bool = field(default=False)
    #: publish each frame with its detections drawn on it on ``<component_name>/visualization``
    #: (an Image topic; the spec's debugging window, made headless). Decided when the component is
    #: defined: the topic is one of its outputs from then on, and setting it to False later only
    #: pauses the pictures.
    enable_visualization: bool = field(default=False, validator=V.instance_of(bool))


class Vision(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = VisionConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = IMAGE_TYPES + (RGBD,)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = DETECTION_OUTPUTS
    PENDING_POLICY: ClassVar[str] = "latest"
    MODEL_OPTIONAL: ClassVar[bool] = True
    STEPS_INSIDE_TICKS: ClassVar[bool] = True

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic], model_client: Any = None,
                 config: VisionConfig | None = None, trigger: Any = 1.0, component_name: str, **kwargs: Any) -> None:
        config = config if config is not None else VisionConfig()
        if model_client is None and not getattr(config, "enable_local_classifier", False):
            raise ValueError(f"component {component_name!r}: Vision needs a model_client or config.enable_local_classifier=True")
        super().__init__(inputs=inputs, outputs=outputs, model_client=None if config.enable_local_classifier else model_client,
                         config=config, trigger=trigger, component_name=component_name, **kwargs)
        self.config: VisionConfig
        if config.enable_local_classifier and model_client is not None:
            self.get_logger().warning("[%s] enable_local_classifier=True: the on-board detector is used, the model client is not",
                                      component_name)
        if not self.in_topics:
            raise ValueError(f"component {component_name!r}: Vision needs an image input")
        if not self.out_topics:
            raise ValueError(f"component {component_name!r}: Vision needs a Detections or Trackings output")
        self.visualization_topic: Topic | None = None
        if self.config.enable_visualization:  # self.config: a config_file may have set it
            self.visualization_topic = Topic(name=f"{component_name}/visualization", msg_type="Image")
            if any(t.name == self.visualization_topic.name for t in self.out_topics):
                raise ValueError(f"component {component_name!r}: enable_visualization publishes on "
                                 f"{self.visualization_topic.name!r}, which is already one of its outputs")
            self.out_topics.append(self.visualization_topic)
        self._local: Any = None
        self._trackers: dict[str, CentroidTracker] = {}
        self.frames_processed = 0

    def activate_resources(self) -> None:
        super().activate_resources()
        if self.config.enable_local_classifier:
            from ..local.vision import LocalDetector

            self._local = LocalDetector(threshold=self.config.threshold)
            self._local.detect(np.zeros((160, 96, 3), np.uint8))  # load the detectors now, not on the first frame
        self._trackers = {t.name: CentroidTracker(self.config.tracking_distance_threshold, self.config.tracking_max_age)
                          for t in self.in_topics}

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        return [] if any(t.name in inputs for t in self.in_topics) else [t.name for t in self.in_topics]

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        frames: list[tuple[str, np.ndarray, Any]] = []
        for t in self.in_topics:
            if t.name not in inputs:
                continue
            try:
                msg = inputs[t.name]
                frames.append((t.name, image_of(msg.rgb if isinstance(msg, RGBD) else msg, t.name), msg))
            except ImageInputError as exc:
                self.health_status.set_fail_system(topic_names=[t.name], message=str(exc))
                self._errors(f"image:{t.name}", "[%s] %s", self.component_name, exc)
                return None
        received = clock.now()  # the node's clock: track velocities in simulated m/s under a simulator
        return lambda: self._detect(frames, received)

    def _detect(self, frames: list[tuple[str, np.ndarray, Any]], stamp: float) -> None:
        if self._local is not None:
            results = [self._local_detections(arr) for _, arr, _ in frames]
        else:
            request = DetectionRequest(images=[arr for _, arr, _ in frames], threshold=self.config.threshold,
                                       labels_to_track=self.config.labels_to_track)
            results = self.call_model(lambda client: client.inference(request)).detections
            if len(results) != len(frames):
                self.health_status.set_fail_algorithm(algorithm_names=[self.model_client_name],
                                                      message=f"{len(results)} results for {len(frames)} images")
                return
        if self.config.labels_to_track:
            keep = set(self.config.labels_to_track)
            results = [_filter(r, keep) for r in results]
        self._publish(frames, results, stamp)
        if self.visualization_topic is not None and self.config.enable_visualization:
            self._publish_visualization(frames, results)
        self.frames_processed += 1
        self.health_status.set_healthy()

    def _local_detections(self, frame: np.ndarray) -> Detection2D:
        import cv2

        h, w = frame.shape[:2]
        scale = min(1.0, self.config.input_width / w, self.config.input_height / h)
        small = cv2.resize(frame, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA) if scale < 1 else frame
        found = self._local.detect(small)
        boxes = np.array([d.box for d in found], dtype=np.float64).reshape(-1, 4) / scale
        return Detection2D(boxes=boxes, labels=[d.label for d in found], scores=[d.score for d in found])

    def _publish(self, frames: list[tuple[str, np.ndarray, Any]], results: list[Detection2D], stamp: float) -> None:
        detections, trackings = [], []
        for (name, arr, msg), result in zip(frames, results):
            header = getattr(msg, "header", None) or header_now()
            image = _attached_image(msg, arr, header, self.config.include_image)
            detections.append(I.Detections(header=header, scores=result.scores, labels=result.labels, boxes=result.boxes, image=image))
            if any(issubclass(t.msg_type, (I.Trackings, I.TrackingsMultiSource)) for t in self.out_topics):
                tr = self._trackers[name].update(result.boxes, result.labels, stamp)
                trackings.append(I.Trackings(header=header, ids=tr.ids, labels=tr.labels, boxes=tr.boxes,
                                             centroids=tr.centroids, estimated_velocities=tr.velocities, image=image))
        for topic in self.out_topics:
            if topic.msg_type is I.Detections:
                self.publish_output(topic, detections[0])
            elif topic.msg_type is I.DetectionsMultiSource:
                self.publish_output(topic, I.DetectionsMultiSource(header=header_now(), detections=detections))
            elif topic.msg_type is I.Trackings:
                self.publish_output(topic, trackings[0])
            elif topic.msg_type is I.TrackingsMultiSource:
                self.publish_output(topic, I.TrackingsMultiSource(header=header_now(), trackings=trackings))

    def _publish_visualization(self, frames: list[tuple[str, np.ndarray, Any]], results: list[Detection2D]) -> None:
        assert self.visualization_topic is not None
        picture = tile([annotate(arr, result) for (_, arr, _), result in zip(frames, results)])
        header = getattr(frames[0][2], "header", None) or header_now()
        self.publish(self.visualization_topic, Image.from_numpy(picture, encoding="rgb8", header=header))


def _attached_image(msg: Any, rgb: np.ndarray, header: Any, include_image: bool) -> Image | None:
    """The image that travels with the detections of ``msg``: an RGBD's depth (always), else the
    frame itself if ``include_image`` (a compressed one as the rgb8 pixels that were detected on)."""
    if isinstance(msg, RGBD):
        return msg.depth
    if not include_image:
        return None
    return msg if isinstance(msg, Image) else Image.from_numpy(rgb, encoding="rgb8", header=header)


def _filter(result: Detection2D, keep: set[str]) -> Detection2D:
    mask = [label in keep for label in result.labels]
    return Detection2D(boxes=result.boxes[mask], labels=[lbl for lbl, m in zip(result.labels, mask) if m],
                       scores=result.scores[mask])
