"""Small audio helpers shared by the local speech models: WAV decoding and resampling."""
from __future__ import annotations

import io
import wave
from math import gcd

import numpy as np


def read_wav(data: bytes) -> tuple[np.ndarray, int]:
    """Decode 8/16/32-bit PCM WAV bytes into (mono float32 samples in [-1, 1], sample rate)."""
    if not isinstance(data, (bytes, bytearray)) or data[:4] != b"RIFF":
        raise ValueError("audio: expected WAV bytes starting with a RIFF header")
    with wave.open(io.BytesIO(bytes(data))) as reader:
        width, channels, rate = reader.getsampwidth(), reader.getnchannels(), reader.getframerate()
        frames = reader.readframes(reader.getnframes())
    if width == 1:
        samples = (np.frombuffer(frames, dtype=np.uint8).astype(np.float32) - 128.0) / 128.0
    elif width == 2:
        samples = np.frombuffer(frames, dtype="<i2").astype(np.float32) / 32768.0
    elif width == 4:
        samples = np.frombuffer(frames, dtype="<i4").astype(np.float32) / 2147483648.0
    else:
        raise ValueError(f"audio: unsupported WAV sample width of {width} bytes")
    if channels > 1:  # downmix: speech models expect mono
        samples = samples.reshape(-1, channels).mean(axis=1)
    return samples, rate


def write_wav(samples: np.ndarray, rate: int) -> bytes:
    """Encode mono float samples in [-1, 1] as 16-bit PCM WAV bytes."""
    pcm = np.clip(np.asarray(samples, dtype=np.float32), -1.0, 1.0)
    buffer = io.BytesIO()
    with wave.open(buffer, "wb") as writer:
        writer.setnchannels(1)
        writer.setsampwidth(2)
        writer.setframerate(int(rate))
        writer.writeframes((pcm * 32767.0).astype("<i2").tobytes())
    return buffer.getvalue()


def resample(samples: np.ndarray, src_rate: int, dst_rate: int) -> np.ndarray:
    """Band-limited polyphase resampling (espeak-ng speaks at 22050 Hz, the models want 16 kHz)."""
    samples = np.asarray(samples, dtype=np.float32)
    if src_rate == dst_rate:
        return samples
    from scipy.signal import resample_poly

    g = gcd(int(src_rate), int(dst_rate))
    return resample_poly(samples, int(dst_rate) // g, int(src_rate) // g).astype(np.float32)


def as_mono_16k(audio: bytes | np.ndarray, sample_rate: int | None = None, target: int = 16000) -> np.ndarray:
    """Accept WAV bytes or a float/int16 array (with its rate) and return float32 mono at ``target``."""
    if isinstance(audio, (bytes, bytearray)):
        samples, rate = read_wav(bytes(audio))
    else:
        if sample_rate is None:
            raise ValueError("audio: a raw sample array needs its sample_rate")
        samples = np.asarray(audio)
        if samples.dtype == np.int16:
            samples = samples.astype(np.float32) / 32768.0
        samples = samples.astype(np.float32).reshape(-1)
        rate = int(sample_rate)
    return resample(samples, rate, target)
