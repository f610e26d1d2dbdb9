"""Offline speech to text with PocketSphinx; its US-English acoustic and language models ship
inside the ``pocketsphinx`` pip package (5.x), so nothing is downloaded.

PocketSphinx is a small HMM recognizer: fine for short commands, far below Whisper on open
dictation. It is the local fallback, not a replacement for a served Whisper model.
"""
from __future__ import annotations

import threading

import numpy as np

from .audio import as_mono_16k

SAMPLE_RATE = 16000


class PocketSphinxSTT:
    """Transcribes audio (WAV bytes or samples) with the packaged en-us model."""

    def __init__(self) -> None:
        try:
            from pocketsphinx import Decoder
        except ImportError as exc:
            raise ImportError("local speech to text needs pocketsphinx: pip install pocketsphinx") from exc
        self._decoder = Decoder(samprate=SAMPLE_RATE, loglevel="FATAL")
        self._lock = threading.Lock()

    def transcribe(self, audio: bytes | np.ndarray, sample_rate: int | None = None) -> str:
        """The recognized words, lower case; "" when nothing was recognized."""
        samples = as_mono_16k(audio, sample_rate, SAMPLE_RATE)
        pcm = (np.clip(samples, -1.0, 1.0) * 32767.0).astype("<i2").tobytes()
        with self._lock:  # one decoder, one utterance at a time
            self._decoder.start_utt()
            self._decoder.process_raw(pcm, full_utt=True)
            self._decoder.end_utt()
            hyp = self._decoder.hyp()
        return hyp.hypstr.strip().lower() if hyp is not None else ""
