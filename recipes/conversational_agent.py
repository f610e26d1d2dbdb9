"""Conversational agent (foundation recipe): speech in, a VLM looks at the camera and answers,
speech out.

    emos serve models --script recipes/models/responder.yaml &     # the model server
    emos run recipes/conversational_agent.py
    EMOS_UI=1 emos run recipes/conversational_agent.py          # with the spec's web UI

Audio comes from the ``audio0`` topic (a microphone driver, or ``emos topic pub``) and the
answer's audio goes to ``audio_out`` and, when this machine has a sound card, its speakers.
Ported from the spec by changing imports; the changes beyond imports are commented.
"""
import os

from emos import Launcher, Topic
from emos.actors.agents import (
    VLM,
    OllamaClient,
    OllamaModel,
    RoboMLWSClient,
    SpeechT5,
    SpeechToText,
    SpeechToTextConfig,
    TextToSpeech,
    TextToSpeechConfig,
    VLMConfig,
    Whisper,
)

# Offline: every model is served by `emos serve models` on this port (see recipes/models/).
MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

audio_in = Topic(name="audio0", msg_type="Audio")
text_query = Topic(name="text0", msg_type="String")

whisper = Whisper(name="whisper")  # Custom model init params can be provided here
roboml_whisper = RoboMLWSClient(whisper, port=MODELS_PORT)

# The wakeword is off: openWakeWord's 'hey jarvis' model cannot be downloaded here, and the
# transcript-based wakeword needs a recognizer that hears the phrase (enable it with a real STT).
s2t_config = SpeechToTextConfig(enable_vad=True, enable_wakeword=False)

speech_to_text = SpeechToText(
    inputs=[audio_in],
    outputs=[text_query],
    model_client=roboml_whisper,
    trigger=audio_in,
    config=s2t_config,
    component_name="speech_to_text",
)

image0 = Topic(name="image_raw", msg_type="Image")
text_answer = Topic(name="text1", msg_type="String")

qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
qwen_client = OllamaClient(qwen_vl, port=MODELS_PORT)
mllm_config = VLMConfig(stream=True)  # Other inference specific parameters can be provided here

mllm = VLM(
    inputs=[text_query, image0],
    outputs=[text_answer],
    model_client=qwen_client,
    trigger=text_query,
    config=mllm_config,
    component_name="vqa",
)
mllm.set_topic_prompt(text_query, template="""You are an amazing and funny robot.
Answer the following about this image: {{ text0 }}""")

# play_on_device plays on the speakers when there are any; the audio also goes to a topic.
t2s_config = TextToSpeechConfig(play_on_device=True, stream=True)
audio_out = Topic(name="audio_out", msg_type="Audio")
speecht5 = SpeechT5(name="speecht5")
roboml_speecht5 = RoboMLWSClient(speecht5, port=MODELS_PORT)
text_to_speech = TextToSpeech(
    inputs=[text_answer],
    outputs=[audio_out],
    trigger=text_answer,
    model_client=roboml_speecht5,
    config=t2s_config,
    component_name="text_to_speech",
)

launcher = Launcher()
# The spec's web UI (speak or type a question, see the camera): with EMOS_UI=1, open the link
# the run prints (docs/ui.md). Off by default, so a headless run (the tests) needs no port 5001.
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(inputs=[audio_in, text_query], outputs=[image0])
launcher.add_pkg(components=[speech_to_text, mllm, text_to_speech])
launcher.bringup()
