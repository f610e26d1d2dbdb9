"""Annotated debug pictures of a ``Vision`` component's detections (``enable_visualization``).

The ROS original opens a pop-up window with the boxes drawn on the frame. A robot is usually
headless, so ours publishes that picture instead, as an ``Image`` on
``<component_name>/visualization``: the web UI (``launcher.enable_ui(outputs=[...])``), Foxglove
(``launcher.enable_foxglove()``) and ``emos topic echo`` show it, locally or from another
machine, and no window is ever opened.
"""
from __future__ import annotations

import zlib
from collections.abc import Sequence

import numpy as np

from ..types import Detection2D

__all__ = ["annotate", "tile", "label_colour"]


def label_colour(label: str) -> tuple[int, int, int]:
    """A bright RGB colour that stays the same for a label across frames and runs."""
    h = zlib.crc32(label.encode("utf-8", "replace"))
    # Spread the hash over the three channels, then lift each into 80..255 so boxes stand out.
    r, g, b = (80 + ((h >> shift) & 0xFF) * 175 // 255 for shift in (0, 8, 16))
    return r, g, b


def annotate(frame: np.ndarray, result: Detection2D) -> np.ndarray:
    """A copy of the (h, w, 3) uint8 RGB ``frame`` with each detection's box and "label score".

    Boxes come from a model server, so they are not trusted: non-finite ones are skipped and
    the rest clipped to the picture."""
    import cv2

    out = np.ascontiguousarray(frame, dtype=np.uint8).copy()
    h, w = out.shape[:2]
    boxes = np.asarray(result.boxes, dtype=np.float64).reshape(-1, 4)
    thickness = max(1, round(min(h, w) / 240))
    scale = max(0.35, min(h, w) / 800)
    for box, label, score in zip(boxes, result.labels, np.asarray(result.scores, dtype=np.float64).ravel()):
        if not np.all(np.isfinite(box)):
            continue
        x1, x2 = (int(np.clip(v, 0, w - 1)) for v in (box[0], box[2]))
        y1, y2 = (int(np.clip(v, 0, h - 1)) for v in (box[1], box[3]))
        colour = label_colour(str(label))
        cv2.rectangle(out, (x1, y1), (x2, y2), colour, thickness)
        text = f"{label} {score:.2f}" if np.isfinite(score) else str(label)
        (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
        ty = y1 - 2 if y1 - th - base - 2 >= 0 else min(h - 1, y1 + th + base + 2)
        cv2.rectangle(out, (x1, ty - th - base), (min(w - 1, x1 + tw + 2), ty), colour, -1)
        cv2.putText(out, text, (x1 + 1, ty - base), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return out


def tile(pictures: Sequence[np.ndarray]) -> np.ndarray:
    """Several annotated frames side by side (scaled to the first one's height): one topic shows
    every camera of a multi-input Vision component."""
    if len(pictures) == 1:
        return pictures[0]
    import cv2

    height = pictures[0].shape[0]
    scaled = [p if p.shape[0] == height else
              cv2.resize(p, (max(1, round(p.shape[1] * height / p.shape[0])), height), interpolation=cv2.INTER_AREA)
              for p in pictures]
    return np.ascontiguousarray(np.hstack(scaled))
