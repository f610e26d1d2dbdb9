"""Specs for HuggingFace checkpoints served by RoboML (or an OpenAI-compatible server)."""
from __future__ import annotations

import attrs

from .base import Model

__all__ = ["TransformersLLM", "TransformersMLLM", "RoboBrain2"]

QUANTIZATIONS: tuple[str | None, ...] = ("4bit", "8bit", None)
# Typed as the field is: attrs takes the validator's type from the default's (else plain str).
_DEFAULT_QUANTIZATION: str | None = "4bit"


@attrs.define(kw_only=True)
class TransformersLLM(Model):
    """An LLM checkpoint from HuggingFace / ModelScope; ``quantization`` is "4bit", "8bit" or None."""

    checkpoint: str = attrs.field(default="microsoft/Phi-3-mini-4k-instruct", validator=attrs.validators.instance_of(str))
    quantization: str | None = attrs.field(default=_DEFAULT_QUANTIZATION, validator=attrs.validators.in_(QUANTIZATIONS))
    system_prompt: str | None = attrs.field(
        default=None, validator=attrs.validators.optional(attrs.validators.instance_of(str))
    )

    INIT_FIELDS = ("checkpoint", "quantization", "system_prompt")


@attrs.define(kw_only=True)
class TransformersMLLM(TransformersLLM):
    """A multimodal (image + text) checkpoint from HuggingFace / ModelScope."""

    checkpoint: str = attrs.field(default="HuggingFaceM4/idefics2-8b", validator=attrs.validators.instance_of(str))


@attrs.define(kw_only=True)
class RoboBrain2(Model):
    """BAAI's RoboBrain 2.0: planning, pointing, affordance, trajectory and grounding outputs."""

    checkpoint: str = attrs.field(default="BAAI/RoboBrain2.0-7B", validator=attrs.validators.instance_of(str))
