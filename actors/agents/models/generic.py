"""Specs for models behind any OpenAI-compatible server (vLLM, LMDeploy, OpenAI, our local server)."""
from __future__ import annotations

import attrs

from emos.config import validators as V

from .base import Model, options_validator
from .languages import LANGUAGE_CODES

__all__ = ["GenericLLM", "GenericMLLM", "GenericTTS", "GenericSTT"]

# Keys accepted in GenericLLM.options: the standard OpenAI sampling parameters.
OPENAI_OPTIONS: dict[str, type] = {
    "temperature": float,
    "top_p": float,
    "max_tokens": int,
    "presence_penalty": float,
    "frequency_penalty": float,
    "stop": list,
    "seed": int,
}


@attrs.define(kw_only=True)
class GenericLLM(Model):
    """An LLM served on ``/v1/chat/completions``. ``options`` are default sampling parameters;
    component-level ``temperature`` / ``max_tokens`` override them."""

    checkpoint: str = attrs.field(default="gpt-4o", validator=attrs.validators.instance_of(str))
    options: dict | None = attrs.field(default=None, validator=options_validator(OPENAI_OPTIONS))

    INIT_FIELDS = ("checkpoint", "options")


@attrs.define(kw_only=True)
class GenericMLLM(GenericLLM):
    """A multimodal (image + text) LLM on an OpenAI-compatible server."""


@attrs.define(kw_only=True)
class GenericTTS(Model):
    """Text to speech on ``/v1/audio/speech``."""

    checkpoint: str = attrs.field(default="tts-1", validator=attrs.validators.instance_of(str))
    voice: str = attrs.field(default="alloy", validator=attrs.validators.instance_of(str))
    speed: float = attrs.field(default=1.0, validator=V.number(ge=0.25, le=4.0))

    INIT_FIELDS = ("checkpoint", "voice", "speed")


def _language(instance, attribute, value) -> None:
    if value is not None and value not in LANGUAGE_CODES:
        raise ValueError(
            f"{type(instance).__name__}.language: expected an ISO-639-1 code such as 'en' or None, got {value!r}"
        )


@attrs.define(kw_only=True)
class GenericSTT(Model):
    """Speech to text on ``/v1/audio/transcriptions``; ``language`` None means auto-detect."""

    checkpoint: str = attrs.field(default="whisper-1", validator=attrs.validators.instance_of(str))
    temperature: float = attrs.field(default=0.0, validator=V.number(ge=0, le=1))
    language: str | None = attrs.field(default=None, validator=_language)

    INIT_FIELDS = ("checkpoint", "language", "temperature")
