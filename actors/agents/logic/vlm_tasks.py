"""Typed results of VLM planning tasks, parsed from model text.

Planning VLMs (RoboBrain 2.0, Qwen-VL, ...) answer pointing, affordance, trajectory and
grounding questions with coordinates written as JSON (``[{"bbox_2d": [...], "label": ...}]``,
``{"point_2d": [x, y]}``) or as plain lists (``[(x1, y1), (x2, y2)]``, ``[x1, y1, x2, y2]``),
often inside prose or code fences. This module accepts those forms and returns arrays of the
right shape, or raises VLMParseError saying what was expected and what came back.
"""
from __future__ import annotations

import json
import re
from typing import Any

import attrs
import numpy as np

from emos.errors import EmosError

TASKS = ("general", "pointing", "affordance", "trajectory", "grounding")
_POINT_KEYS = ("point_2d", "point", "points", "coordinates")
_BOX_KEYS = ("bbox_2d", "bbox", "box", "boxes")
_NUMBER = r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?"
_GROUP = re.compile(rf"[\(\[]\s*({_NUMBER}(?:\s*,\s*{_NUMBER})+)\s*[\)\]]")
_FENCE = re.compile(r"```(?:json|python)?\s*(.*?)```", re.S)


class VLMParseError(EmosError, ValueError):
    """The model text does not contain the structure the task asks for."""

    def __init__(self, task: str, expected: str, text: str) -> None:
        excerpt = text if len(text) <= 200 else text[:200] + "..."
        super().__init__(f"{task} output: expected {expected}, got {excerpt!r}")
        self.task, self.expected, self.text = task, expected, text


@attrs.frozen
class GeneralResult:
    text: str


@attrs.frozen
class PointingResult:
    points: np.ndarray = attrs.field(eq=False)  # (n, 2) pixel x, y


@attrs.frozen
class TrajectoryResult:
    points: np.ndarray = attrs.field(eq=False)  # (n, 2), in order of travel


@attrs.frozen
class AffordanceResult:
    boxes: np.ndarray = attrs.field(eq=False)  # (n, 4) xyxy


@attrs.frozen
class GroundingResult:
    boxes: np.ndarray = attrs.field(eq=False)  # (n, 4) xyxy
    labels: list[str | None] = attrs.field(factory=list)


def _json_candidates(text: str) -> list[Any]:
    """Every JSON value found in fenced blocks, the whole text, or its outermost brackets."""
    sources = [m.group(1) for m in _FENCE.finditer(text)] + [text]
    found = []
    for source in sources:
        source = source.strip()
        for opener, closer in (("[", "]"), ("{", "}")):
            start, end = source.find(opener), source.rfind(closer)
            if start >= 0 and end > start:
                try:
                    found.append(json.loads(source[start:end + 1]))
                except ValueError:
                    pass
    return found


def _numbers(value: Any) -> list[float] | None:
    if isinstance(value, (list, tuple)) and value and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return [float(v) for v in value]
    return None


def _from_json(value: Any, size: int, keys: tuple[str, ...]) -> tuple[list[list[float]], list[str | None]]:
    """Groups of ``size`` numbers (and their labels) from a decoded JSON value."""
    groups: list[list[float]] = []
    labels: list[str | None] = []

    def visit(item: Any, label: str | None) -> None:
        flat = _numbers(item)
        if flat is not None:
            if len(flat) == size:
                groups.append(flat)
                labels.append(label)
            elif len(flat) % size == 0 and len(flat) > size:  # [x1, y1, x2, y2, ...] flattened
                for i in range(0, len(flat), size):
                    groups.append(flat[i:i + size])
                    labels.append(label)
            return
        if isinstance(item, dict):
            item_label = item.get("label", label)
            item_label = str(item_label) if item_label is not None else None
            for key in keys:
                if key in item:
                    visit(item[key], item_label)
            return
        if isinstance(item, (list, tuple)):
            for sub in item:
                visit(sub, label)

    visit(value, None)
    return groups, labels


def _groups(text: str, size: int, keys: tuple[str, ...]) -> tuple[np.ndarray, list[str | None]]:
    for candidate in _json_candidates(text):
        groups, labels = _from_json(candidate, size, keys)
        if groups:
            return np.asarray(groups, dtype=np.float64), labels
    # Plain coordinate lists inside prose: "(x, y)" or "[x1, y1, x2, y2]" groups.
    groups = [[float(v) for v in m.group(1).split(",")] for m in _GROUP.finditer(text)]
    groups = [g for g in groups if len(g) == size]
    return np.asarray(groups, dtype=np.float64).reshape(-1, size), [None] * len(groups)


def _check_boxes(task: str, boxes: np.ndarray, text: str) -> np.ndarray:
    if not np.all(np.isfinite(boxes)):
        raise VLMParseError(task, "finite box coordinates", text)
    bad = (boxes[:, 2] < boxes[:, 0]) | (boxes[:, 3] < boxes[:, 1])
    if np.any(bad):
        raise VLMParseError(task, "boxes as [x1, y1, x2, y2] with x2 >= x1 and y2 >= y1", text)
    return boxes


def parse_vlm_output(task: str, text: str):
    """Parse a model's answer for ``task`` into its typed result."""
    if task not in TASKS:
        raise ValueError(f"task {task!r}: expected one of {TASKS}")
    if not isinstance(text, str):
        raise TypeError(f"{task} output: expected model text, got {type(text).__name__}")
    if task == "general":
        return GeneralResult(text.strip())
    if task in ("pointing", "trajectory"):
        points, _ = _groups(text, 2, _POINT_KEYS)
        need = 2 if task == "trajectory" else 1
        if len(points) < need or not np.all(np.isfinite(points)):
            raise VLMParseError(task, f"at least {need} point(s) as (x, y) or JSON point_2d", text)
        return PointingResult(points) if task == "pointing" else TrajectoryResult(points)
    boxes, labels = _groups(text, 4, _BOX_KEYS)
    if len(boxes) == 0:
        raise VLMParseError(task, "at least one box as [x1, y1, x2, y2] or JSON bbox_2d", text)
    boxes = _check_boxes(task, boxes, text)
    if task == "affordance":
        return AffordanceResult(boxes)
    return GroundingResult(boxes, labels)
