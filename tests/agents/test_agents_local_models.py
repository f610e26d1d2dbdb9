"""The offline local models on real inputs: packaged weights, generated speech and images."""
from __future__ import annotations

import io
import os
import wave

import numpy as np
import pytest

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.local.audio import read_wav, resample, write_wav  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.local.embeddings import SentenceEmbedder  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.local.tts import EspeakTTS, TTSError  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import


# ----------------------------------------------------------------- embeddings
def test_embeddings_are_normalized_and_semantic():
    embedder = SentenceEmbedder()
    vectors = embedder.embed(["Go to the kitchen", "Walk into the kitchen", "What is the capital of France?"])
    assert vectors.shape == (3, embedder.dimension) == (3, 384) and vectors.dtype == np.float32
    assert np.allclose(np.linalg.norm(vectors, axis=1), 1.0, atol=1e-5)
    sims = vectors @ vectors.T
    assert sims[0, 1] > sims[0, 2] + 0.2  # paraphrases are much closer than unrelated text
    assert embedder.embed([]).shape == (0, 384)


def test_embedder_model_is_cached_per_process_and_validates_input():
    a, b = SentenceEmbedder(), SentenceEmbedder()
    assert a._model is b._model
    with pytest.raises(TypeError, match="list of strings"):
        a.embed("one string")
    with pytest.raises(TypeError, match="item 1"):
        a.embed(["ok", 3])
    with pytest.raises(FileNotFoundError, match="does not exist"):
        SentenceEmbedder("/nonexistent/model/dir")


# ----------------------------------------------------------------- text to speech
def test_espeak_produces_a_valid_wav_whose_length_follows_speed():
    tts = EspeakTTS()
    slow = tts.synthesize("The robot is going to the kitchen now.", speed_wpm=100)
    fast = tts.synthesize("The robot is going to the kitchen now.", speed_wpm=300)
    with wave.open(io.BytesIO(slow)) as reader:  # strict reader: header sizes must be right
        assert reader.getnchannels() == 1 and reader.getsampwidth() == 2
        assert reader.getnframes() * 2 + 44 <= len(slow)
    slow_s, rate = read_wav(slow)
    fast_s, _ = read_wav(fast)
    assert len(slow_s) > 1.8 * len(fast_s)
    assert np.abs(slow_s).max() > 0.05  # not silence


def test_espeak_errors_are_clear():
    tts = EspeakTTS()
    with pytest.raises(ValueError, match="non-empty"):
        tts.synthesize("   ")
    with pytest.raises(ValueError, match="speed_wpm"):
        tts.synthesize("hi", speed_wpm=0)
    # out-of-range rates are clamped to what espeak-ng can speak
    assert len(tts.synthesize("hello there", speed_wpm=5)) == len(tts.synthesize("hello there", speed_wpm=80))
    with pytest.raises(TTSError, match="voice"):
        tts.synthesize("hi", voice="nonexistentvoice")
    with pytest.raises(FileNotFoundError, match="apt-get install -y espeak-ng"):
        EspeakTTS(binary="espeak-ng-not-installed")


def test_wav_round_trip_and_resample():
    t = np.arange(22050) / 22050.0
    tone = 0.5 * np.sin(2 * np.pi * 440 * t).astype(np.float32)
    samples, rate = read_wav(write_wav(tone, 22050))
    assert rate == 22050 and np.allclose(samples, tone, atol=1e-3)
    down = resample(tone, 22050, 16000)
    assert len(down) == 16000
    spectrum = np.abs(np.fft.rfft(down))
    assert abs(np.argmax(spectrum) - 440) <= 1  # 1 s of audio: bin index == Hz
    with pytest.raises(ValueError, match="RIFF"):
        read_wav(b"not a wav")


# ----------------------------------------------------------------- voice activity
def test_vad_finds_speech_and_ignores_silence_and_noise():
    from emos.actors.agents.local.vad import SileroVAD

    speech, rate = read_wav(EspeakTTS().synthesize("Hello robot, please bring me a glass of water."))
    rng = np.random.default_rng(7)
    silence = np.zeros(rate, np.float32)
    noise = rng.normal(0, 0.05, 2 * rate).astype(np.float32)
    audio = np.concatenate([silence, noise, speech, silence])
    vad = SileroVAD()
    segments = vad.segments(audio, rate)
    assert len(segments) >= 1
    start, end = segments[0].start_s, segments[-1].end_s
    speech_start, speech_end = 3.0, 3.0 + len(speech) / rate
    assert abs(start - speech_start) < 0.4 and abs(end - speech_end) < 0.5
    assert vad.segments(np.concatenate([silence, noise, silence]), rate) == []
    assert vad.contains_speech(write_wav(audio, rate))  # WAV bytes are accepted too
    with pytest.raises(ValueError, match="sample_rate"):
        vad.segments(audio)


# ----------------------------------------------------------------- speech to text
def test_pocketsphinx_transcribes_synthetic_speech_partially():
    from emos.actors.agents.local.stt import PocketSphinxSTT

    stt = PocketSphinxSTT()
    text = stt.transcribe(EspeakTTS().synthesize("what is the weather like", speed_wpm=140))
    # PocketSphinx's acoustic model is trained on human voices; on espeak's formant voice it
    # gets some words right only, so only the leading words are asserted.
    assert text.startswith("what is")


# ----------------------------------------------------------------- vision
def _figure(scale: float = 0.8) -> np.ndarray:
    import cv2

    img = np.full((400, 300, 3), 200, np.uint8)
    def p(x, y):
        return int(150 + x * scale), int(40 + y * scale)
    ink = (40, 40, 40)
    cv2.circle(img, p(0, 20), int(16 * scale), ink, -1)
    cv2.fillPoly(img, [np.array([p(-28, 42), p(28, 42), p(22, 140), p(-22, 140)])], ink)
    for (x0, y0, x1, y1, w) in ((-26, 48, -40, 135, 11), (26, 48, 40, 135, 11),
                                (-12, 138, -18, 250, 16), (12, 138, 18, 250, 16)):
        cv2.line(img, p(x0, y0), p(x1, y1), ink, int(w * scale))
    return img


def test_hog_detects_a_rendered_person_and_nothing_in_empty_scenes():
    from emos.actors.agents.local.vision import LocalDetector

    detector = LocalDetector(labels=("person",))
    (person,) = detector.detect(_figure())
    assert person.label == "person" and 0.5 < person.score <= 1.0
    x1, y1, x2, y2 = person.box
    assert x1 < 150 < x2 and y1 < 120 < y2  # the box covers the figure's torso
    rng = np.random.default_rng(0)
    assert detector.detect(np.full((300, 300, 3), 128, np.uint8)) == []
    assert detector.detect(rng.integers(0, 255, (300, 300, 3), dtype=np.uint8)) == []


def test_haar_detects_the_face_in_a_real_photograph():
    mpl_data = pytest.importorskip("matplotlib", reason="the test photograph ships with matplotlib "
                                   "(emos[plots])").get_data_path()
    import cv2

    from emos.actors.agents.local.vision import LocalDetector

    photo = cv2.imread(os.path.join(mpl_data, "sample_data", "grace_hopper.jpg"))[:, :, ::-1].copy()
    detections = LocalDetector().detect(photo)
    faces = [d for d in detections if d.label == "face"]
    assert len(faces) == 1 and faces[0].score > 0.5
    x1, y1, x2, y2 = faces[0].box
    assert 100 < (x1 + x2) / 2 < 400 and 100 < (y1 + y2) / 2 < 350  # her face, upper middle


def test_detector_input_validation():
    from emos.actors.agents.local.vision import LocalDetector

    with pytest.raises(ValueError, match="labels"):
        LocalDetector(labels=("cat",))
    with pytest.raises(ValueError, match="uint8"):
        LocalDetector().detect(np.zeros((64, 64, 3), np.float32))
    with pytest.raises(ValueError, match="shape"):
        LocalDetector().detect(np.zeros((64,), np.uint8))
