"""Issue 33 D7: ``TextToSpeech(play_on_device=True)`` without an audio output device (this
machine has none: no PortAudio) reports SYSTEM_FAILURE naming the device for as long as it
runs, keeps publishing its audio, and an ``on_system_fail`` fallback acts on it."""
from __future__ import annotations

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.runtime.helpers import SystemUnderTest, wait_until

NO_DEVICE = "is not available here"


def _tts(**config):
    from emos import Topic
    from emos.actors.agents import RoboMLWSClient, SpeechT5, TextToSpeech, TextToSpeechConfig

    return TextToSpeech(inputs=[Topic(name="text_in", msg_type="String")], outputs=[Topic(name="audio", msg_type="Audio")],
                        model_client=RoboMLWSClient(SpeechT5(name="speecht5"), port=1), component_name="tts",
                        config=TextToSpeechConfig(**config))


@pytest.mark.unit
@pytest.mark.parametrize(("device", "named"), [(None, "the default audio output device"), ("speakers", "audio output device 'speakers'")])
def test_missing_output_device_is_a_system_failure_naming_it(device, named):
    tts = _tts(play_on_device=True, device=device)
    try:
        tts.activate_resources()
        assert tts.health_status.is_system_fail
        assert f"play_on_device: {named} {NO_DEVICE}" in tts.health_status.message
        tts._set_healthy()  # what a spoken text ends with: the device is still missing
        assert tts.health_status.is_system_fail
    finally:
        tts.release_resources()


@pytest.mark.unit
def test_without_play_on_device_nothing_is_reported():
    tts = _tts(play_on_device=False)
    tts.activate_resources()
    tts._set_healthy()
    assert tts.health_status.is_healthy and tts.health_status.message == ""


@pytest.fixture(scope="module")
def tts_server():
    from tests.agents.fixtures.server_process import start_server

    proc = start_server()
    yield proc
    proc.stop()


@pytest.mark.process
def test_tts_without_device_reports_publishes_and_its_fallback_acts(tmp_path, tts_server):
    system = SystemUnderTest(tmp_path, f"""
from emos.actors.agents import TextToSpeech, TextToSpeechConfig, RoboMLWSClient, SpeechT5
from emos.actions import publish_message

text_in = Topic(name="text_in", msg_type="String")
audio = Topic(name="audio", msg_type="Audio")
noticed = Topic(name="tts_fallback", msg_type="String")
tts = TextToSpeech(inputs=[text_in], outputs=[audio], trigger=text_in, component_name="tts",
                   model_client=RoboMLWSClient(SpeechT5(name="speecht5"), port={tts_server.port}),
                   config=TextToSpeechConfig(play_on_device=True))
tts.on_system_fail(action=publish_message(topic=noticed, msg=M.String(data="no speakers")))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[tts])
launcher.bringup()
""").wait_up(components=["tts"])
    probe = Probe(system)
    try:
        probe.sub("/tts_fallback", "String")
        status = wait_until(lambda: (s := probe.status("tts")).status == M.ComponentStatus.STATUS_FAILURE_SYSTEM_LEVEL and s,
                            what="SYSTEM_FAILURE of tts")
        assert f"play_on_device: the default audio output device {NO_DEVICE}" in status.message
        (fallback,) = probe.collect("/tts_fallback", "String")[:1]
        assert fallback.data == "no speakers"
        probe.pub("/text_in", M.String(data="hello there"))
        (spoken,) = probe.collect("/audio", "Audio", timeout=60)[:1]
        assert spoken.data.size > 1000  # still published
        # having spoken does not make it healthy: the device is still missing
        wait_until(lambda: probe.status("tts").header.stamp.to_sec() > status.header.stamp.to_sec() + 0.5, what="a later status")
        assert probe.status("tts").status == M.ComponentStatus.STATUS_FAILURE_SYSTEM_LEVEL
        assert NO_DEVICE in system.output()  # and the log says so, naming the component
        assert "[tts] play_on_device:" in system.output()
    finally:
        probe.close()
        system.stop()
