"""Messages in, python values out (and back): what agent components read and publish.

Components think in values (a question is a ``str``, a frame an (h, w, 3) array, a goal an
``[x, y, z]`` array); topics carry messages. Input conversion turns a received message into the
value a model request needs; output conversion turns a model result (after the topic's publisher
preprocessors) into a message of the output topic's type, or fails with an error that names the
topic, the type it carries and the value it was given.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from emos.core import clock
from emos.errors import EmosError
from emos.msgs import geometry as G
from emos.msgs import intelligence as I
from emos.msgs import nav as N
from emos.msgs import sensor as S
from emos.msgs import std as D
from emos.msgs.std import Header

from ..logic.detections import NOTHING

TEXT_TYPES = (D.String, I.StreamingString)
IMAGE_TYPES = (S.Image, S.CompressedImage)
#: types whose content can become prompt text
TEXTUAL_TYPES = (D.String, I.StreamingString, I.Detections, I.DetectionsMultiSource, I.Trackings, I.TrackingsMultiSource)
POSITION_TYPES = (G.PoseStamped, G.Pose, G.Point, G.PointStamped)


class OutputConversionError(EmosError, TypeError):
    """A component's output cannot be published on a topic of that type."""


class ImageInputError(EmosError, ValueError):
    """An image message that cannot be read as pixels (wrong shape, encoding or size)."""


def header_now(frame_id: str = "") -> Header:
    """A header stamped on the node's clock (simulated seconds when a simulator drives the run)."""
    return Header(stamp=clock.stamp(), frame_id=frame_id)


# ------------------------------------------------------------------------------ inputs
def detections_text(msg: Any) -> str:
    """Labels of a Detections/Trackings message (or multi-source) as prompt text."""
    if isinstance(msg, (I.DetectionsMultiSource,)):
        parts = [detections_text(d) for d in msg.detections]
    elif isinstance(msg, I.TrackingsMultiSource):
        parts = [detections_text(t) for t in msg.trackings]
    else:
        labels = list(msg.labels)
        if not labels:
            return NOTHING
        from collections import Counter

        counts = Counter(labels)
        return ", ".join(label if n == 1 else f"{label} x{n}" for label, n in counts.most_common())
    parts = [p for p in parts if p != NOTHING]
    return ", ".join(parts) if parts else NOTHING


def text_of(msg: Any) -> str:
    if isinstance(msg, TEXT_TYPES):
        return msg.data
    if isinstance(msg, (I.Detections, I.DetectionsMultiSource, I.Trackings, I.TrackingsMultiSource)):
        return detections_text(msg)
    raise TypeError(f"cannot read text from a {type(msg).__name__} message")


def image_of(msg: Any, topic: str = "image") -> np.ndarray:
    """(h, w, 3) uint8 RGB pixels of an Image or CompressedImage message."""
    if isinstance(msg, S.CompressedImage):
        import cv2

        data = np.asarray(msg.data, dtype=np.uint8)
        decoded = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
        if decoded is None:
            raise ImageInputError(f"{topic}: compressed image ({msg.format or 'unknown format'}, {data.size} bytes) could not be decoded")
        return np.ascontiguousarray(decoded[:, :, ::-1])
    if not isinstance(msg, S.Image):
        raise ImageInputError(f"{topic}: expected an Image or CompressedImage, got {type(msg).__name__}")
    if msg.encoding not in S.IMAGE_ENCODINGS:
        raise ImageInputError(f"{topic}: image encoding {msg.encoding!r} is not supported; expected one of {sorted(S.IMAGE_ENCODINGS)}")
    dtype, channels = S.IMAGE_ENCODINGS[msg.encoding]
    need = msg.height * max(msg.step, msg.width * channels * np.dtype(dtype).itemsize)
    if msg.height == 0 or msg.width == 0 or len(msg.data) != need:
        raise ImageInputError(f"{topic}: {msg.encoding} image of {msg.width}x{msg.height} (step {msg.step}) "
                              f"needs {need} bytes, got {len(msg.data)}")
    arr = msg.to_numpy()
    if dtype != "uint8":  # depth/mono16: scale to 8 bits for models that want pictures
        arr = arr.astype(np.float64)
        hi = float(np.nanmax(arr)) if arr.size else 0.0
        arr = (np.nan_to_num(arr) * (255.0 / hi if hi > 0 else 0)).astype(np.uint8)
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    elif msg.encoding in ("bgr8", "bgra8"):
        arr = arr[:, :, 2::-1]
    elif arr.shape[2] == 4:
        arr = arr[:, :, :3]
    return np.ascontiguousarray(arr)


def position_of(msg: Any) -> np.ndarray:
    """[x, y, z] of an Odometry, PoseStamped, Pose, Point or PointStamped message."""
    if isinstance(msg, N.Odometry):
        p = msg.pose.pose.position
    elif isinstance(msg, G.PoseStamped):
        p = msg.pose.position
    elif isinstance(msg, G.Pose):
        p = msg.position
    elif isinstance(msg, G.PointStamped):
        p = msg.point
    elif isinstance(msg, G.Point):
        p = msg
    else:
        raise TypeError(f"cannot read a position from a {type(msg).__name__} message")
    return np.array([p.x, p.y, p.z], dtype=np.float64)


# ------------------------------------------------------------------------------ outputs
def _vector(value: Any, topic: str, type_name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise OutputConversionError(f"output {topic!r} ({type_name}) needs [x, y] or [x, y, z] numbers, got {value!r}") from None
    if arr.size not in (2, 3) or not np.all(np.isfinite(arr)):
        raise OutputConversionError(f"output {topic!r} ({type_name}) needs 2 or 3 finite numbers, got {arr.tolist()}")
    return np.append(arr, 0.0) if arr.size == 2 else arr


def to_message(msg_type: type, value: Any, topic: str = "output", frame_id: str = "") -> Any:
    """A message of ``msg_type`` carrying ``value``."""
    if isinstance(value, msg_type):
        return value
    name = msg_type.__name__
    if msg_type is D.String:
        if isinstance(value, str):
            return D.String(data=value)
        raise OutputConversionError(f"output {topic!r} (String) needs text, got {type(value).__name__}; "
                                    "add a publisher preprocessor that returns a str")
    if msg_type is I.StreamingString and isinstance(value, str):
        return I.StreamingString(stream=False, done=True, data=value)
    if msg_type in POSITION_TYPES:
        x, y, z = _vector(value, topic, name)
        point = G.Point(x=x, y=y, z=z)
        if msg_type is G.Point:
            return point
        if msg_type is G.PointStamped:
            return G.PointStamped(header=header_now(frame_id), point=point)
        pose = G.Pose(position=point)
        return pose if msg_type is G.Pose else G.PoseStamped(header=header_now(frame_id), pose=pose)
    if msg_type is S.Audio:
        if isinstance(value, (bytes, bytearray)):
            return S.Audio(data=np.frombuffer(bytes(value), dtype=np.uint8))
        if isinstance(value, np.ndarray):
            return S.Audio(data=np.ascontiguousarray(value).reshape(-1).view(np.uint8))
    if msg_type is S.Image and isinstance(value, np.ndarray):
        return S.Image.from_numpy(value, "mono8" if value.ndim == 2 else "rgb8", header=header_now(frame_id))
    if msg_type in (D.Float32, D.Float64, D.Int32, D.Int64, D.Bool) and np.isscalar(value):
        return msg_type(data=value)
    if msg_type in (D.Float32MultiArray, D.Float64MultiArray):
        return msg_type(data=np.asarray(value, dtype=np.float32 if msg_type is D.Float32MultiArray else np.float64).reshape(-1))
    raise OutputConversionError(f"output {topic!r} ({name}) cannot carry a {type(value).__name__}: {str(value)[:80]!r}")
