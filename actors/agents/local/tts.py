"""Text to speech through the espeak-ng binary (Debian package ``espeak-ng``).

espeak-ng is a formant synthesizer: robotic-sounding but tiny, fast and fully offline, which
makes it a dependable local fallback for a TextToSpeech component.
"""
from __future__ import annotations

import shutil
import subprocess

from emos.errors import EmosError

_MIN_WPM, _MAX_WPM = 80, 500


class TTSError(EmosError, RuntimeError):
    """espeak-ng failed to synthesize the given text."""


class EspeakTTS:
    """Synthesizes WAV bytes (16-bit mono, 22050 Hz) with espeak-ng."""

    def __init__(self, binary: str = "espeak-ng", default_voice: str = "en-us",
                 timeout_s: float = 30.0) -> None:
        path = shutil.which(binary)
        if path is None:
            raise FileNotFoundError(
                f"text to speech needs the {binary!r} binary on PATH; install it with "
                "'apt-get install -y espeak-ng' (also done by scripts/setup.sh)"
            )
        self.binary = path
        self.default_voice = default_voice
        self.timeout_s = timeout_s

    def synthesize(self, text: str, voice: str | None = None, speed_wpm: int | None = None) -> bytes:
        """Return a complete WAV file (RIFF header included) speaking ``text``."""
        if not isinstance(text, str) or not text.strip():
            raise ValueError("EspeakTTS.synthesize: text must be a non-empty string")
        cmd = [self.binary, "--stdout", "-v", voice or self.default_voice]
        if speed_wpm is not None:
            if isinstance(speed_wpm, bool) or not isinstance(speed_wpm, (int, float)) or not speed_wpm > 0:
                raise ValueError(f"speed_wpm: expected a positive number of words per minute, got {speed_wpm!r}")
            # espeak-ng only speaks between ~80 and ~500 wpm; callers map relative speeds
            # (OpenAI's 0.25x..4x) onto wpm, so out-of-range requests get the nearest rate.
            cmd += ["-s", str(int(min(max(round(speed_wpm), _MIN_WPM), _MAX_WPM)))]
        # Text goes through stdin so that a leading '-' is never read as an option.
        cmd.append("--stdin")
        try:
            proc = subprocess.run(cmd, input=text.encode("utf-8"), capture_output=True,
                                  timeout=self.timeout_s, check=False)
        except subprocess.TimeoutExpired as exc:
            raise TTSError(f"espeak-ng took longer than {self.timeout_s} s") from exc
        stderr = proc.stderr.decode("utf-8", "replace").strip()
        if proc.returncode != 0 or not proc.stdout.startswith(b"RIFF"):
            raise TTSError(f"espeak-ng failed (exit {proc.returncode}): {stderr or 'no WAV output'}")
        if stderr:  # espeak-ng exits 0 on an unknown voice but says so on stderr
            raise TTSError(f"espeak-ng: {stderr}")
        return _fix_wav_sizes(proc.stdout)


def _fix_wav_sizes(wav: bytes) -> bytes:
    """espeak-ng writing to a pipe cannot seek back, so it leaves the RIFF and data sizes as
    0xFFFFFFFF; patch them so strict readers (the ``wave`` module, browsers) accept the file."""
    if len(wav) < 44 or wav[:4] != b"RIFF":
        return wav
    data_at = wav.find(b"data", 12)
    if data_at < 0:
        return wav
    out = bytearray(wav)
    out[4:8] = (len(wav) - 8).to_bytes(4, "little")
    out[data_at + 4:data_at + 8] = (len(wav) - data_at - 8).to_bytes(4, "little")
    return bytes(out)
