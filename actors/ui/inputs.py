"""What the page sends, checked and turned into messages. Nothing is published unless it fits.

Every function raises :class:`InputRefused` with a sentence naming the topic and what it expected.
"""
from __future__ import annotations

import io
import math
import wave
from typing import Any

import numpy as np

from emos.actors.ui.widgets import input_kind
from emos.core import clock
from emos.errors import EmosError
from emos.msgs import codec
from emos.msgs.geometry import Point, Pose, Quaternion
from emos.msgs.registry import resolve
from emos.msgs.sensor import Image
from emos.msgs.std import Header

_INT_BOUNDS = {"Int32": (-(2**31), 2**31 - 1), "Int64": (-(2**63), 2**63 - 1), "UInt8": (0, 255)}
AUDIO_RATE = 16000


class InputRefused(EmosError, ValueError):
    """A value from the page that does not fit its topic."""


def _number(topic: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputRefused(f"{topic}: expected a finite number, got {value!r}")
    return value


def message_from_page(topic: str, type_name: str, value: Any, frame_id: str = "map") -> Any:
    """The message to publish on ``topic`` for a value the page sent (JSON-decoded)."""
    cls = resolve(type_name)
    kind = input_kind(type_name)
    if kind == "text":
        if not isinstance(value, str):
            raise InputRefused(f"{topic}: expected text, got {type(value).__name__}")
        return cls(data=value)
    if kind == "bool":
        if not isinstance(value, bool):
            raise InputRefused(f"{topic}: expected true or false, got {value!r}")
        return cls(data=value)
    if kind == "number":
        number = _number(topic, value)
        if type_name in _INT_BOUNDS:
            lo, hi = _INT_BOUNDS[type_name]
            if number != int(number) or not lo <= number <= hi:
                raise InputRefused(f"{topic}: {type_name} takes a whole number in [{lo}, {hi}], got {value!r}")
            number = int(number)
        return cls(data=number)
    if kind == "goal":
        if not isinstance(value, dict) or "x" not in value or "y" not in value:
            raise InputRefused(f"{topic}: expected a goal {{x, y[, yaw]}} in metres, got {value!r}")
        x, y = _number(topic, value["x"]), _number(topic, value["y"])
        header = Header(stamp=clock.stamp(), frame_id=str(value.get("frame_id") or frame_id))  # the run's clock, as the robot's own stamps
        if type_name == "PointStamped":
            return cls(header=header, point=Point(x=x, y=y, z=0.0))
        yaw = _number(topic, value.get("yaw", 0.0))
        return cls(header=header, pose=Pose(position=Point(x=x, y=y, z=0.0),
                                            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))
    if kind in ("audio", "image"):
        raise InputRefused(f"{topic}: {type_name} is sent as a file upload, not as a value")
    if not isinstance(value, dict):
        raise InputRefused(f"{topic}: expected the fields of {type_name} as an object, got {type(value).__name__}")
    try:
        return codec.from_builtin(cls, value)
    except (TypeError, ValueError) as exc:
        raise InputRefused(f"{topic}: {exc}") from None


def message_from_upload(topic: str, type_name: str, body: bytes) -> Any:
    """An Audio message from a WAV file (16 kHz mono 16-bit) or an Image from a picture file."""
    if not body:
        raise InputRefused(f"{topic}: the upload is empty")
    cls = resolve(type_name)
    if type_name == "Audio":
        try:
            with wave.open(io.BytesIO(body)) as w:
                if (w.getnchannels(), w.getsampwidth(), w.getframerate()) != (1, 2, AUDIO_RATE):
                    raise InputRefused(f"{topic}: audio must be {AUDIO_RATE} Hz mono 16-bit PCM WAV, got "
                                       f"{w.getframerate()} Hz, {w.getnchannels()} channel(s), {8 * w.getsampwidth()}-bit")
                pcm = w.readframes(w.getnframes())
        except (wave.Error, EOFError) as exc:
            raise InputRefused(f"{topic}: not a WAV file ({exc})") from None
        return cls(data=np.frombuffer(pcm, np.uint8))
    if type_name == "Image":
        from emos.actors.ui.codecs import _backend

        try:
            if _backend() == "cv2":
                import cv2

                bgr = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR)
                if bgr is None:
                    raise ValueError("not a picture OpenCV can read")
                rgb = bgr[:, :, ::-1]
            else:
                from PIL import Image as PILImage

                rgb = np.asarray(PILImage.open(io.BytesIO(body)).convert("RGB"))
        except Exception as exc:
            raise InputRefused(f"{topic}: cannot read the uploaded picture ({exc})") from None
        return Image.from_numpy(np.ascontiguousarray(rgb), encoding="rgb8", header=Header(stamp=clock.stamp()))
    raise InputRefused(f"{topic}: {type_name} does not take uploads")


_GOAL_TYPES = ("PoseStamped", "PointStamped", "Pose", "Point")


def goal_field(goal_cls: type) -> str | None:
    """The field of an action goal a click on the map fills: the goal itself if it is a pose or a
    point, else its first pose or point field (``None`` if it has none)."""
    import attrs

    if goal_cls.__name__ in _GOAL_TYPES:
        return ""
    for f in attrs.fields(goal_cls):
        cls = (f.metadata or {}).get("cls")
        cls = cls() if callable(cls) and not isinstance(cls, type) else cls
        if isinstance(cls, type) and cls.__name__ in _GOAL_TYPES:
            return f.name
    return None


def _pose_like(cls: type, topic: str, value: dict[str, Any]) -> Any:
    name = cls.__name__
    if name in ("PoseStamped", "PointStamped"):
        return message_from_page(topic, name, value)
    stamped = message_from_page(topic, "PoseStamped", value)
    return stamped.pose if name == "Pose" else stamped.pose.position


def goal_from_page(action: str, goal_cls: type, value: Any) -> Any:
    """An action goal from the page: a map click ``{x, y[, yaw]}`` fills the goal's pose or point
    field; anything else is the goal's fields as an object."""
    import attrs

    if isinstance(value, dict) and set(value) <= {"x", "y", "yaw", "frame_id"} and {"x", "y"} <= set(value):
        name = goal_field(goal_cls)
        if name == "":
            return _pose_like(goal_cls, action, value)
        if name is not None:
            field = next(f for f in attrs.fields(goal_cls) if f.name == name)
            cls = field.metadata["cls"]
            cls = cls() if callable(cls) and not isinstance(cls, type) else cls
            try:
                return goal_cls(**{name: _pose_like(cls, action, value)})
            except TypeError as exc:
                raise InputRefused(f"{action}: {goal_cls.__name__} needs more than a point: {exc}") from None
    if not isinstance(value, dict):
        raise InputRefused(f"{action}: expected the fields of {goal_cls.__name__} as an object, got {type(value).__name__}")
    try:
        return codec.from_builtin(goal_cls, value)
    except (TypeError, ValueError) as exc:
        raise InputRefused(f"{action}: {exc}") from None
