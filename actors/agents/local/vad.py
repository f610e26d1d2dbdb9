"""Voice activity detection with Silero VAD, whose weights ship in the ``silero-vad`` package."""
from __future__ import annotations

import threading
from typing import Any

import attrs
import numpy as np

from .audio import as_mono_16k

SAMPLE_RATE = 16000
_MODEL: Any = None
_LOCK = threading.Lock()


@attrs.frozen
class SpeechSegment:
    """A stretch of speech, in seconds from the start of the audio."""

    start_s: float
    end_s: float

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


def _model() -> Any:
    global _MODEL
    with _LOCK:
        if _MODEL is None:
            try:
                from silero_vad import load_silero_vad
            except ImportError as exc:  # pragma: no cover - depends on the environment
                raise ImportError("voice activity detection needs silero-vad: pip install 'emos[agents]'") from exc
            # The TorchScript weights load from the package directory: no download.
            _MODEL = load_silero_vad(onnx=False)
        return _MODEL


@attrs.define(kw_only=True)
class SileroVAD:
    """Finds speech segments in audio. Parameters mirror Silero's own defaults."""

    threshold: float = attrs.field(default=0.5, validator=[attrs.validators.gt(0.0), attrs.validators.lt(1.0)])
    min_speech_duration_ms: int = attrs.field(default=250, validator=attrs.validators.ge(0))
    min_silence_duration_ms: int = attrs.field(default=100, validator=attrs.validators.ge(0))
    speech_pad_ms: int = attrs.field(default=30, validator=attrs.validators.ge(0))

    def segments(self, audio: bytes | np.ndarray, sample_rate: int | None = None) -> list[SpeechSegment]:
        """Speech segments in WAV bytes or a sample array (any rate; resampled to 16 kHz)."""
        import torch
        from silero_vad import get_speech_timestamps

        samples = as_mono_16k(audio, sample_rate, SAMPLE_RATE)
        if samples.size == 0:
            return []
        model = _model()
        with _LOCK:  # the model keeps recurrent state: one caller at a time
            stamps = get_speech_timestamps(
                torch.from_numpy(np.ascontiguousarray(samples)), model, threshold=self.threshold,
                sampling_rate=SAMPLE_RATE, min_speech_duration_ms=self.min_speech_duration_ms,
                min_silence_duration_ms=self.min_silence_duration_ms, speech_pad_ms=self.speech_pad_ms)
        return [SpeechSegment(s["start"] / SAMPLE_RATE, s["end"] / SAMPLE_RATE) for s in stamps]

    def contains_speech(self, audio: bytes | np.ndarray, sample_rate: int | None = None) -> bool:
        return bool(self.segments(audio, sample_rate))
