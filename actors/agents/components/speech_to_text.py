"""``SpeechToText``: audio in, text out.

Without VAD every ``Audio`` message is one utterance (WAV bytes, or raw 16 kHz mono int16 PCM)
and is transcribed as it comes. With ``enable_vad=True`` messages are chunks of a continuous
stream (a microphone or a topic): the on-board Silero VAD finds speech, and an utterance goes
to the model once ``min_silence_duration_ms`` of silence follow it (or the buffer is full).
With ``enable_wakeword=True`` only utterances that begin with ``wakeword`` (default "hey
jarvis") are published, without the wakeword; a wakeword alone arms the next utterance. The
wakeword is matched on the transcript (the openWakeWord ONNX models of the original cannot be
downloaded here), so it costs one transcription per utterance.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs import sensor as S
from emos.msgs import std as D

from ..local.audio import read_wav, write_wav
from ..models.languages import LANGUAGE_CODES
from ..types import TranscriptionRequest
from .base import ModelComponent, ModelComponentConfig

RATE = 16000


def _language(instance: Any, attribute: Any, value: Any) -> None:
    if value is not None and value not in LANGUAGE_CODES:
        raise ValueError(f"SpeechToTextConfig.language: expected an ISO-639-1 code such as 'en' or None, got {value!r}")


@define(kw_only=True)
class SpeechToTextConfig(ModelComponentConfig):
    initial_prompt: str | None = field(default=None)
    language: str | None = field(default="en", validator=_language)
    enable_vad: bool = field(default=False)
    vad_threshold: float = field(default=0.5, validator=V.in_range(0.01, 0.99))
    min_silence_duration_ms: int = field(default=300, validator=V.in_range(0, 60_000))
    speech_pad_ms: int = field(default=30, validator=V.in_range(0, 10_000))
    #: longest utterance kept, in ms; a longer one is cut and transcribed in pieces
    speech_buffer_max_ms: int = field(default=30_000, validator=V.in_range(500, 600_000))
    enable_wakeword: bool = field(default=False)
    wakeword: str = field(default="hey jarvis")
    #: accepted for the spec's recipes: transcripts are published whole (on a StreamingString
    #: output as one piece marked done), the local speech-to-text cannot stream partial words
    stream: bool = field(default=False)
    max_pending: int = field(default=512, validator=V.in_range(1, 100_000))  # audio chunks are never dropped lightly

    def __attrs_post_init__(self) -> None:
        if self.enable_wakeword and not self.enable_vad:
            raise ValueError("SpeechToTextConfig: enable_wakeword=True needs enable_vad=True (the wakeword is looked for in utterances the VAD finds)")
        if self.enable_wakeword and not self.wakeword.strip():
            raise ValueError("SpeechToTextConfig.wakeword: expected a non-empty phrase")


def pcm_of(msg: S.Audio) -> np.ndarray:
    """Float32 mono samples at 16 kHz of an Audio message (WAV bytes or raw int16 PCM)."""
    raw = np.asarray(msg.data, dtype=np.uint8).tobytes()
    if raw[:4] == b"RIFF":
        from ..local.audio import resample

        samples, rate = read_wav(raw)
        return resample(samples, rate, RATE)
    if len(raw) % 2:
        raise ValueError(f"raw audio must be 16-bit PCM (an even number of bytes), got {len(raw)} bytes")
    return np.frombuffer(raw, dtype="<i2").astype(np.float32) / 32768.0


class SpeechToText(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = SpeechToTextConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (S.Audio,)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = (D.String, I.StreamingString)

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic], model_client: Any, config: SpeechToTextConfig | None = None,
                 trigger: Any = 1.0, component_name: str, **kwargs: Any) -> None:
        super().__init__(inputs=inputs, outputs=outputs, model_client=model_client, config=config, trigger=trigger,
                         component_name=component_name, **kwargs)
        self.config: SpeechToTextConfig
        if not self.in_topics or not self.out_topics:
            raise ValueError(f"component {component_name!r}: SpeechToText needs an Audio input and a String output")
        self._vad: Any = None
        self._buffer = np.zeros(0, np.float32)
        self._armed = False  # the wakeword was heard alone: the next utterance is for us

    def activate_resources(self) -> None:
        super().activate_resources()
        self._buffer = np.zeros(0, np.float32)
        self._armed = False
        if self.config.enable_vad:
            from ..local.vad import SileroVAD

            cfg = self.config
            self._vad = SileroVAD(threshold=cfg.vad_threshold, min_silence_duration_ms=cfg.min_silence_duration_ms,
                                  speech_pad_ms=cfg.speech_pad_ms)
            self._vad.segments(np.zeros(RATE // 10, np.float32), RATE)  # load the model now

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        return [] if self.in_topics[0].name in inputs else [self.in_topics[0].name]

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        topic = self.in_topics[0].name
        msg = inputs[topic]
        if len(msg.data) == 0:
            self.health_status.set_fail_system(topic_names=[topic], message=f"{topic}: empty audio chunk")
            self._errors("empty", "[%s] %s: empty audio chunk ignored", self.component_name, topic)
            return None
        # Decoding (and resampling) runs in the worker: the event loop only hands the bytes over.
        return lambda: self._chunk(topic, msg)

    # ------------------------------------------------------------------ worker side
    def _chunk(self, topic: str, msg: S.Audio) -> None:
        try:
            samples = pcm_of(msg)
        except ValueError as exc:
            self.health_status.set_fail_system(topic_names=[topic], message=f"{topic}: {exc}")
            self._errors("audio", "[%s] %s: %s", self.component_name, topic, exc)
            return
        if self.config.enable_vad:
            self._feed(samples)
        else:
            self._utterance(samples)

    def _feed(self, samples: np.ndarray) -> None:
        cfg = self.config
        self._buffer = np.concatenate([self._buffer, samples])
        segments = self._vad.segments(self._buffer, RATE)
        if not segments:
            # Keep a second: the VAD only reports speech once it lasted min_speech_duration_ms
            # (250 ms), so the start of a word must still be in the buffer when it does.
            keep = int(RATE * (1.0 + cfg.speech_pad_ms / 1000))
            self._buffer = self._buffer[-keep:]
            self.health_status.set_healthy()
            return
        buffered_s = len(self._buffer) / RATE
        silence_after = buffered_s - segments[-1].end_s
        full = buffered_s * 1000 >= cfg.speech_buffer_max_ms
        if silence_after * 1000 < cfg.min_silence_duration_ms and not full:
            return  # still speaking
        pad = cfg.speech_pad_ms / 1000
        start = max(0, int((segments[0].start_s - pad) * RATE))
        end = min(len(self._buffer), int((segments[-1].end_s + pad) * RATE))
        utterance = self._buffer[start:end]
        self._buffer = self._buffer[end:]
        self._utterance(utterance)

    def _utterance(self, samples: np.ndarray) -> None:
        if samples.size == 0 or float(np.max(np.abs(samples))) < 1e-4:
            self.health_status.set_healthy()  # silence: nothing to say, nothing wrong
            return
        request = TranscriptionRequest(audio=write_wav(samples, RATE), language=self.config.language,
                                       prompt=self.config.initial_prompt)
        text = self.call_model(lambda client: client.inference(request)).text.strip()
        self.get_logger().debug("[%s] utterance of %.2f s: %r", self.component_name, samples.size / RATE, text)
        if self.config.enable_wakeword:
            text = self._after_wakeword(text)
        if text:
            self.publish_all(text)
        self.health_status.set_healthy()

    def _after_wakeword(self, text: str) -> str:
        words = re.findall(r"[\w']+", text.lower())
        wake = re.findall(r"[\w']+", self.config.wakeword.lower())
        if words[: len(wake)] == wake:
            rest = text.split(None, len(wake))[len(wake):]  # keep the original spelling of the rest
            rest_text = rest[0].strip() if rest else ""
            self._armed = not rest_text
            return rest_text
        if self._armed:
            self._armed = False
            return text
        return ""
