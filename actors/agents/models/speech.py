"""Specs for speech models served by RoboML: Whisper (STT); SpeechT5, Bark and MeloTTS (TTS)."""
from __future__ import annotations

import attrs

from .base import Model

__all__ = ["Whisper", "SpeechT5", "Bark", "MeloTTS"]

WHISPER_SIZES = (
    "tiny", "tiny.en", "base", "base.en", "small", "small.en", "distil-small.en", "medium",
    "medium.en", "distil-medium.en", "large-v1", "large-v2", "large-v3", "large", "distil-large-v2",
    "distil-large-v3", "large-v3-turbo", "turbo",
)
WHISPER_COMPUTE_TYPES: tuple[str | None, ...] = ("int8", "float16", "float32", None)
# Typed as the field is: attrs takes the validator's type from the default's (else plain str).
_DEFAULT_COMPUTE_TYPE: str | None = "int8"


def _whisper_checkpoint(instance, attribute, value) -> None:
    # A size name, or a path / repo id (contains "/") for a converted custom checkpoint.
    if not isinstance(value, str) or (value not in WHISPER_SIZES and "/" not in value):
        raise ValueError(f"Whisper.checkpoint: expected one of {WHISPER_SIZES} or a repo id/path, got {value!r}")


@attrs.define(kw_only=True)
class Whisper(Model):
    """OpenAI's Whisper ASR (faster-whisper sizes); ``compute_type`` int8, float16, float32 or None."""

    checkpoint: str = attrs.field(default="small.en", validator=_whisper_checkpoint)
    compute_type: str | None = attrs.field(
        default=_DEFAULT_COMPUTE_TYPE, validator=attrs.validators.in_(WHISPER_COMPUTE_TYPES)
    )

    INIT_FIELDS = ("checkpoint", "compute_type")


SPEECHT5_VOICES = ("awb", "bdl", "clb", "jmk", "ksp", "rms", "slt")


@attrs.define(kw_only=True)
class SpeechT5(Model):
    """Microsoft's SpeechT5 TTS with one of the CMU Arctic speaker ``voice``s."""

    checkpoint: str = attrs.field(default="microsoft/speecht5_tts", validator=attrs.validators.instance_of(str))
    voice: str = attrs.field(default="clb", validator=attrs.validators.in_(SPEECHT5_VOICES))

    INIT_FIELDS = ("checkpoint", "voice")


@attrs.define(kw_only=True)
class Bark(Model):
    """Suno's Bark TTS; ``voice`` is a Bark speaker preset such as ``v2/en_speaker_6``."""

    checkpoint: str = attrs.field(default="suno/bark-small", validator=attrs.validators.instance_of(str))
    voice: str = attrs.field(default="v2/en_speaker_6", validator=attrs.validators.instance_of(str))

    INIT_FIELDS = ("checkpoint", "voice")


MELO_LANGUAGES = ("EN", "ES", "FR", "ZH", "JP", "KR")


@attrs.define(kw_only=True)
class MeloTTS(Model):
    """MyShell's multilingual MeloTTS; ``speaker_id`` must belong to ``language`` (``JP`` -> ``JP-1``)."""

    language: str = attrs.field(default="EN", validator=attrs.validators.in_(MELO_LANGUAGES))
    speaker_id: str = attrs.field(default="EN-US", validator=attrs.validators.instance_of(str))

    INIT_FIELDS = ("language", "speaker_id")

    def __attrs_post_init__(self) -> None:
        # EN speakers are EN-US, EN-BR, EN_INDIA, EN-AU, EN-Default; others are e.g. JP-1... or "ZH".
        if not self.speaker_id.upper().startswith(self.language):
            raise ValueError(
                f"MeloTTS.speaker_id: expected a speaker of language {self.language!r} "
                f"(e.g. '{self.language}-1'), got {self.speaker_id!r}"
            )
