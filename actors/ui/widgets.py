"""Which widget shows or feeds a topic, chosen by its message type.

Output kinds (what the page shows): text, number, bool, image, audio, map, pose, path, generic.
Input kinds (what the page lets the user send): text, bool, number, goal (click on the map),
audio (microphone or file), image (file), form (any other type, as its fields).
"""
from __future__ import annotations

from typing import Any

OUTPUT_KINDS: dict[str, str] = {
    "String": "text", "StreamingString": "text",
    "Float32": "number", "Float64": "number", "Int32": "number", "Int64": "number", "UInt8": "number",
    "Bool": "bool",
    "Image": "image", "CompressedImage": "image", "Detections": "image",
    "Audio": "audio",
    "OccupancyGrid": "map",
    "Odometry": "pose", "PoseStamped": "pose", "PoseWithCovarianceStamped": "pose", "Pose2D": "pose",
    "Path": "path",
}

INPUT_KINDS: dict[str, str] = {
    "String": "text",
    "Bool": "bool",
    "Float32": "number", "Float64": "number", "Int32": "number", "Int64": "number", "UInt8": "number",
    "PoseStamped": "goal", "PointStamped": "goal",
    "Audio": "audio",
    "Image": "image",
}

# Hub families: every message kept (in a bounded history), the latest value only, or an encoded
# frame sent under flow control.
LOG_KINDS = {"text", "number"}
FRAME_KINDS = {"image", "audio", "map"}


def output_kind(type_name: str) -> str:
    return OUTPUT_KINDS.get(type_name, "generic")


def input_kind(type_name: str) -> str:
    return INPUT_KINDS.get(type_name, "form")


def describe_fields(cls: Any) -> list[dict[str, Any]]:
    """The top-level fields of a message type for a generic input form (name and JSON default)."""
    import attrs

    from emos.actors.ui.codecs import summarize

    try:
        example = cls()
    except Exception:  # a type without defaults: the form starts empty
        return [{"name": f.name} for f in attrs.fields(cls)]
    return [{"name": f.name, "default": summarize(getattr(example, f.name), 8)} for f in attrs.fields(cls)]
