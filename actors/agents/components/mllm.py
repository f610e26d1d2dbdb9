"""``MLLM`` (alias ``VLM``): the LLM component with images.

Every image input's latest frame goes with the prompt. With ``task`` set ("pointing",
"affordance", "trajectory", "grounding" or "general") the answer is parsed into its typed result
and published on the matching outputs: points on ``PointsOfInterest``, boxes on ``Detections``,
the text itself on ``String``.
"""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.msgs import intelligence as I
from emos.msgs import std as D

from ..logic.vlm_tasks import (TASKS, AffordanceResult, GeneralResult, GroundingResult, PointingResult,
                               TrajectoryResult, VLMParseError, parse_vlm_output)
from ..types import ImageData
from .convert import IMAGE_TYPES, TEXTUAL_TYPES, ImageInputError, header_now, image_of
from .llm import LLM, LLM_OUTPUTS, LLMConfig


def _task(instance: Any, attribute: Any, value: Any) -> None:
    if value is not None and value not in TASKS:
        raise ValueError(f"MLLMConfig.task: expected None or one of {TASKS}, got {value!r}")


@define(kw_only=True)
class MLLMConfig(LLMConfig):
    task: str | None = field(default=None, validator=_task)


VLMConfig = MLLMConfig


class MLLM(LLM):
    CONFIG_CLASS: ClassVar[type] = MLLMConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = TEXTUAL_TYPES + IMAGE_TYPES
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = LLM_OUTPUTS + (I.Detections, I.PointsOfInterest)

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.config: MLLMConfig
        if not self.image_inputs:
            raise ValueError(f"component {self.component_name!r}: {type(self).__name__} needs an image input (Image or CompressedImage)")

    @property
    def image_inputs(self) -> list:
        return [t for t in self.input_topics if issubclass(t.msg_type, IMAGE_TYPES)]

    def missing_inputs(self, inputs: dict[str, Any]) -> list[str]:
        missing = super().missing_inputs(inputs)
        if not any(t.name in inputs for t in self.image_inputs):
            missing += [t.name for t in self.image_inputs]
        return missing

    def images(self, inputs: dict[str, Any]) -> list[ImageData] | None:
        out = []
        for t in self.image_inputs:
            if t.name not in inputs:
                continue
            try:
                out.append(ImageData.from_array(image_of(inputs[t.name], t.name)))
            except ImageInputError as exc:
                exc.topic = t.name  # type: ignore[attr-defined]
                raise
        return out

    def transform_answer(self, text: str) -> Any:
        return text

    def deliver(self, text: str, user: Any) -> None:
        task = self.config.task
        if task is None:
            return super().deliver(text, user)
        try:
            result = parse_vlm_output(task, text)
        except VLMParseError as exc:
            self.health_status.set_fail_algorithm(algorithm_names=[f"vlm_task_{task}"], message=str(exc))
            self._errors("task", "[%s] %s", self.component_name, exc)
            return
        self.publish_all(text, (D.String, I.StreamingString))
        if isinstance(result, (PointingResult, TrajectoryResult)):
            msg = I.PointsOfInterest(header=header_now(), points=result.points)
            self.publish_all(msg, (I.PointsOfInterest,))
        elif isinstance(result, (GroundingResult, AffordanceResult)):
            labels = [lbl or task for lbl in getattr(result, "labels", [])] or [task] * len(result.boxes)
            msg = I.Detections(header=header_now(), scores=np.ones(len(result.boxes)), labels=labels, boxes=result.boxes)
            self.publish_all(msg, (I.Detections,))
        elif not isinstance(result, GeneralResult):  # pragma: no cover - parse_vlm_output covers every task
            raise TypeError(f"unexpected VLM result {type(result).__name__}")
        self._remember(user, text)
        self.health_status.set_healthy()


VLM = MLLM
