"""Detections as prompt text, e.g. for ``This image has following items: {{ detections }}``."""
from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

NOTHING = "nothing"


def _fields(item: Any) -> tuple[str, float | None, tuple[float, ...] | None]:
    if isinstance(item, Mapping):
        label, score, box = item.get("label"), item.get("score"), item.get("box")
    else:
        label, score, box = getattr(item, "label", None), getattr(item, "score", None), getattr(item, "box", None)
    if not isinstance(label, str) or not label:
        raise ValueError(f"detection {item!r}: expected a non-empty 'label'")
    return label, (None if score is None else float(score)), (None if box is None else tuple(float(v) for v in box))


def detections_to_text(detections: Iterable[Any], with_boxes: bool = False, with_scores: bool = False,
                       min_score: float = 0.0) -> str:
    """Summarize detections (objects or dicts with label, score, box).

    Without boxes or scores, labels are counted ("person x2, chair"), most frequent first;
    with them, every detection is listed ("person (0.91) at [10, 20, 50, 120]").
    """
    items = [_fields(d) for d in detections]
    items = [d for d in items if d[1] is None or d[1] >= min_score]
    if not items:
        return NOTHING
    if not (with_boxes or with_scores):
        counts = Counter(label for label, _, _ in items)
        return ", ".join(label if n == 1 else f"{label} x{n}" for label, n in counts.most_common())
    parts = []
    for label, score, box in items:
        text = label
        if with_scores and score is not None:
            text += f" ({score:.2f})"
        if with_boxes and box is not None:
            text += " at [" + ", ".join(f"{v:.0f}" for v in box) + "]"
        parts.append(text)
    return ", ".join(parts)
