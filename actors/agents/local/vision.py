"""Local object detection with detectors whose weights ship inside OpenCV (4.x wheels):
the HOG + linear SVM pedestrian detector ("person") and the frontal-face Haar cascade ("face").

They are classic, CPU-cheap detectors: good enough as the Vision component's on-board fallback
and for tests, not a replacement for a served neural detector.
"""
from __future__ import annotations

import threading
from typing import Any

import attrs
import numpy as np

LABELS = ("person", "face")


@attrs.frozen
class Detection:
    """One detection: label, confidence in [0, 1] and an ``xyxy`` pixel box."""

    label: str
    score: float
    box: tuple[float, float, float, float]


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("the local Vision detector needs OpenCV: pip install 'emos[agents]'") from exc
    if not hasattr(cv2, "HOGDescriptor") or not hasattr(cv2, "CascadeClassifier"):
        raise ImportError(f"OpenCV {cv2.__version__} has no HOG/Haar detectors (removed in 5.x): "
                          "pip install 'opencv-python-headless>=4.8,<5'")
    return cv2


def _squash(margin: np.ndarray, scale: float) -> np.ndarray:
    """Map an unbounded detector margin (SVM distance, cascade level weight) to (0, 1)."""
    return 1.0 / (1.0 + np.exp(-np.asarray(margin, dtype=np.float64) / scale))


def _nms(boxes: np.ndarray, scores: np.ndarray, iou: float) -> np.ndarray:
    """Greedy non-maximum suppression over xyxy boxes; returns kept indices, best first."""
    order = np.argsort(-scores)
    keep: list[int] = []
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    while order.size:
        i, rest = order[0], order[1:]
        keep.append(int(i))
        xx1 = np.maximum(boxes[i, 0], boxes[rest, 0])
        yy1 = np.maximum(boxes[i, 1], boxes[rest, 1])
        xx2 = np.minimum(boxes[i, 2], boxes[rest, 2])
        yy2 = np.minimum(boxes[i, 3], boxes[rest, 3])
        inter = np.clip(xx2 - xx1, 0, None) * np.clip(yy2 - yy1, 0, None)
        overlap = inter / np.maximum(area[i] + area[rest] - inter, 1e-9)
        order = rest[overlap <= iou]
    return np.array(keep, dtype=int)


@attrs.define(kw_only=True)
class LocalDetector:
    """Runs the packaged OpenCV detectors on an image (HxWx3 RGB/BGR or HxW grey uint8).

    ``threshold`` filters on the squashed score, like the Vision component's ``threshold``.
    """

    labels: tuple[str, ...] = attrs.field(default=LABELS, converter=tuple)
    threshold: float = attrs.field(default=0.5, validator=[attrs.validators.ge(0.0), attrs.validators.le(1.0)])
    nms_iou: float = attrs.field(default=0.4, validator=[attrs.validators.gt(0.0), attrs.validators.le(1.0)])
    _hog: Any = attrs.field(default=None, init=False, repr=False)
    _face: Any = attrs.field(default=None, init=False, repr=False)
    _lock: threading.Lock = attrs.field(factory=threading.Lock, init=False, repr=False)

    @labels.validator
    def _check_labels(self, attribute, value) -> None:
        unknown = [v for v in value if v not in LABELS]
        if unknown or not value:
            raise ValueError(f"LocalDetector.labels: expected a non-empty subset of {LABELS}, got {value}")

    def _load(self) -> None:
        cv2 = _cv2()
        if "person" in self.labels and self._hog is None:
            hog = cv2.HOGDescriptor()
            hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
            self._hog = hog
        if "face" in self.labels and self._face is None:
            path = cv2.data.haarcascades + "haarcascade_frontalface_default.xml"
            face = cv2.CascadeClassifier(path)
            if face.empty():
                raise FileNotFoundError(f"Haar cascade {path!r} could not be loaded")
            self._face = face

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Detections sorted by score, best first."""
        image = np.asarray(image)
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)) or image.size == 0:
            raise ValueError(f"image: expected HxW or HxWx3/4 pixels, got shape {image.shape}")
        if image.dtype != np.uint8:
            raise ValueError(f"image: expected uint8 pixels, got {image.dtype}")
        cv2 = _cv2()
        with self._lock:  # OpenCV detector objects are not documented as thread-safe
            self._load()
            grey = image if image.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(image[:, :, :3]),
                                                              cv2.COLOR_RGB2GRAY)
            out: list[Detection] = []
            if self._hog is not None:
                out += self._people(cv2, grey)
            if self._face is not None:
                out += self._faces(cv2, grey)
        return sorted(out, key=lambda d: -d.score)

    def _people(self, cv2, grey: np.ndarray) -> list[Detection]:
        win_w, win_h = self._hog.winSize
        if grey.shape[0] < win_h or grey.shape[1] < win_w:
            # No person fits; and OpenCV's HOG segfaults on images smaller than its window.
            return []
        rects, weights = self._hog.detectMultiScale(grey, winStride=(4, 4), padding=(8, 8), scale=1.05)
        if len(rects) == 0:
            return []
        # SVM margins of pedestrians are typically 0.5..3; scale 1 puts margin 0 at score 0.5.
        return self._boxes("person", np.asarray(rects, float), _squash(np.ravel(weights), 1.0))

    def _faces(self, cv2, grey: np.ndarray) -> list[Detection]:
        rects, _, weights = self._face.detectMultiScale3(grey, scaleFactor=1.1, minNeighbors=5,
                                                         outputRejectLevels=True)
        if len(rects) == 0:
            return []
        # Last-stage level weights of real faces are a few units: scale 2 keeps them near 0.8-0.95.
        return self._boxes("face", np.asarray(rects, float), _squash(np.ravel(weights), 2.0))

    def _boxes(self, label: str, xywh: np.ndarray, scores: np.ndarray) -> list[Detection]:
        boxes = np.column_stack([xywh[:, 0], xywh[:, 1], xywh[:, 0] + xywh[:, 2], xywh[:, 1] + xywh[:, 3]])
        keep = _nms(boxes, scores, self.nms_iou)
        return [Detection(label, float(scores[i]), (float(boxes[i, 0]), float(boxes[i, 1]),
                                                    float(boxes[i, 2]), float(boxes[i, 3])))
                for i in keep if scores[i] >= self.threshold]
