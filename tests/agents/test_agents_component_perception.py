"""Vision, TextToSpeech and SpeechToText as real processes with the real local models."""
from __future__ import annotations

import io
import wave

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.test_agents_local_models import _figure
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

HEADER = AGENT_HEADER + """
from emos.actors.agents import Vision, VisionConfig, SpeechToText, SpeechToTextConfig, TextToSpeech, TextToSpeechConfig
from emos.actors.agents import RoboMLWSClient, Whisper, SpeechT5
"""


def _wav_seconds(data: bytes) -> float:
    with wave.open(io.BytesIO(data)) as w:
        return w.getnframes() / w.getframerate()


def test_vision_detects_and_tracks_with_the_onboard_classifier(tmp_path):
    system = SystemUnderTest(tmp_path, HEADER + """
image = Topic(name="image_raw", msg_type="Image")
dets = Topic(name="detections", msg_type="Detections")
tracks = Topic(name="trackings", msg_type="Trackings")
vision = Vision(inputs=[image], outputs=[dets, tracks], trigger=image, component_name="vision",
                config=VisionConfig(threshold=0.5, enable_local_classifier=True, tracking_distance_threshold=60))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vision])
launcher.bringup()
""", duration=120).wait_up(components=["vision"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/detections", "Detections"), probe.sub("/trackings", "Trackings")
        wait_until(lambda: probe.status("vision").status == M.ComponentStatus.STATUS_HEALTHY, 30, what="vision ready")
        figure = _figure()
        probe.pub("/image_raw", M.Image.from_numpy(figure))
        (det,) = probe.collect("/detections", "Detections")
        assert det.labels == ["person"] and det.scores[0] >= 0.5
        x1, y1, x2, y2 = det.boxes[0]
        assert x1 < 150 < x2 and y1 < 120 < y2
        shifted = np.full_like(figure, 200)
        shifted[:, 10:] = figure[:, :-10]  # the person moved 10 px to the right
        probe.pub("/image_raw", M.Image.from_numpy(shifted))
        first, second = probe.collect("/trackings", "Trackings", 2)
        assert list(first.ids) == list(second.ids) and len(second.ids) == 1
        assert second.estimated_velocities[0, 0] > 0  # moving right
        probe.collect("/detections", "Detections")  # the shifted frame's detections
        # A frame whose bytes do not match its size: a system-level failure naming the topic.
        probe.pub("/image_raw", M.Image(height=480, width=640, encoding="rgb8", step=1920, data=np.zeros(10, np.uint8)))
        wait_until(lambda: probe.status("vision").src_topics == ["/image_raw"], 10, what="the bad frame reported")
        assert probe.drain("/detections", "Detections") == []
    finally:
        probe.close()
        assert system.stop() == 0


def test_speech_round_trip_tts_to_stt_with_and_without_vad(tmp_path, model_server):
    system = SystemUnderTest(tmp_path, HEADER + f"""
text_in = Topic(name="text_in", msg_type="String")
audio = Topic(name="audio", msg_type="Audio")
mic = Topic(name="mic", msg_type="Audio")
heard = Topic(name="heard", msg_type="String")
heard_vad = Topic(name="heard_vad", msg_type="String")
tts = TextToSpeech(inputs=[text_in], outputs=[audio], trigger=text_in, component_name="tts",
                   model_client=RoboMLWSClient(SpeechT5(name="speecht5"), port={model_server.port}))
stt = SpeechToText(inputs=[audio], outputs=[heard], trigger=audio, component_name="stt",
                   model_client=RoboMLWSClient(Whisper(name="whisper"), port={model_server.port}))
stt_vad = SpeechToText(inputs=[mic], outputs=[heard_vad], trigger=mic, component_name="stt_vad",
                       model_client=RoboMLWSClient(Whisper(name="whisper2"), port={model_server.port}),
                       config=SpeechToTextConfig(enable_vad=True, min_silence_duration_ms=300))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[tts, stt, stt_vad])
launcher.bringup()
""", duration=150).wait_up(components=["tts", "stt", "stt_vad"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/audio", "Audio"), probe.sub("/heard", "String"), probe.sub("/heard_vad", "String")
        for name in ("tts", "stt", "stt_vad"):
            wait_until(lambda name=name: probe.status(name).status == M.ComponentStatus.STATUS_HEALTHY, 60, what=f"{name} ready")
        probe.pub("/text_in", M.String(data="what is the weather like"))
        (spoken,) = probe.collect("/audio", "Audio", timeout=60)
        wav = spoken.data.tobytes()
        assert 0.8 < _wav_seconds(wav) < 5.0
        (heard,) = probe.collect("/heard", "String", timeout=60)
        assert heard.data.startswith("what is")  # PocketSphinx on espeak's voice: the leading words
        # The same speech as a microphone stream: 32 ms chunks of raw PCM, then silence.
        from emos.actors.agents.local.audio import read_wav, resample

        samples, rate = read_wav(wav)
        pcm = np.concatenate([np.zeros(8000, np.float32), resample(samples, rate, 16000), np.zeros(16000, np.float32)])
        ints = (pcm * 32767).astype("<i2")
        probe.pub("/mic", M.Audio(data=np.zeros(0, np.uint8)))  # an empty chunk: reported, ignored
        wait_until(lambda: "empty audio chunk" in probe.status("stt_vad").message, 10, what="the empty chunk reported")
        import time

        for start in range(0, len(ints), 512):  # a microphone's pace (32 ms chunks), a little faster
            probe.pub("/mic", M.Audio(data=ints[start:start + 512].view(np.uint8)))
            time.sleep(0.02)
        (heard_vad,) = probe.collect("/heard_vad", "String", timeout=60)
        assert heard_vad.data.startswith("what is")
        # say() as an action target: called through the component's control socket.
        from emos.core.node import control_socket
        from emos.core.rpc import RpcClient

        with RpcClient(control_socket(system.ctx, "tts")) as rpc:
            assert rpc.call("execute_method", method="say", args=["hello robot"]) is True
            said = probe.collect("/audio", "Audio", timeout=60)[0].data.tobytes()
            assert 0.3 < _wav_seconds(said) < 3.0
            assert rpc.call("execute_method", method="stop_playback") is True
        # Silence alone produces no text.
        for _ in range(20):
            probe.pub("/mic", M.Audio(data=np.zeros(1024, np.uint8)))
        assert probe.drain("/heard_vad", "String", settle=1.5) == []
    finally:
        probe.close()
        assert system.stop() == 0
