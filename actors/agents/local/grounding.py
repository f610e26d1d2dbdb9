"""Visual grounding with the local detector: "the person by the door" -> boxes of people.

A planning VLM (RoboBrain 2.0) grounds a free-form description in the image. The local model
server cannot run one, so it grounds with what it has: it finds which class of the local
detector (:mod:`.vision`) the description names, runs the detector on the image and answers with
the boxes of that class, best first. It is a real answer about the picture (no person in view,
no box), limited to the classes the detector knows.
"""
from __future__ import annotations

import re
from collections.abc import Sequence

from .vision import LABELS, Detection

__all__ = ["SYNONYMS", "named_class", "ground", "box_centres"]

#: words of a description that name each detector class
SYNONYMS: dict[str, tuple[str, ...]] = {
    "person": ("person", "persons", "people", "human", "humans", "man", "men", "woman", "women", "someone",
               "somebody", "pedestrian", "pedestrians", "child", "kid", "guy", "lady", "boy", "girl"),
    "face": ("face", "faces"),
}
_WORD = re.compile(r"[a-z]+")


def named_class(description: str, labels: Sequence[str] = LABELS) -> str | None:
    """The detector class the description names (the first one mentioned), or None."""
    words = _WORD.findall(description.lower())
    for word in words:
        for label in labels:
            if word in SYNONYMS.get(label, (label,)):
                return label
    return None


def ground(detections: Sequence[Detection], description: str, labels: Sequence[str] = LABELS) -> list[list[float]]:
    """xyxy boxes (best first) of the detections of the class the description names; empty if it
    names no known class or none is in view."""
    label = named_class(description, labels)
    if label is None:
        return []
    found = sorted((d for d in detections if d.label == label), key=lambda d: -d.score)
    return [[round(v, 1) for v in d.box] for d in found]


def box_centres(boxes: Sequence[Sequence[float]]) -> list[list[float]]:
    """Pointing answers from grounding boxes: the centre (x, y) of each."""
    return [[round(0.5 * (b[0] + b[2]), 1), round(0.5 * (b[1] + b[3]), 1)] for b in boxes]
