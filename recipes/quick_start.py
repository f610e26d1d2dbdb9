"""Quick start (getting-started/quickstart.md): a VLM answers questions about the camera image.

    emos serve models --script recipes/models/responder.yaml &     # the model server
    emos run recipes/quick_start.py
    emos topic pub /text0 String '{"data": "What do you see?"}'    # (and images on /image_raw)
    emos topic echo /text1
    EMOS_UI=1 emos run recipes/quick_start.py                   # with the page's web UI

The spec's code with its imports changed; the Ollama client talks to `emos serve models` on
EMOS_MODELS_PORT (the page's own note: ``OllamaClient(qwen_vl, host=..., port=...)``). The
page's last section adds ``launcher.enable_ui(...)``: on with EMOS_UI=1, so a headless run
(the tests) needs no port 5001.
"""
import os

from emos import Launcher, Topic
from emos.actors.agents import VLM, OllamaClient, OllamaModel

# Offline: the model is served by `emos serve models` on this port (see recipes/models/).
MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

# Define input and output topics (pay attention to msg_type)
text0 = Topic(name="text0", msg_type="String")
image0 = Topic(name="image_raw", msg_type="Image")
text1 = Topic(name="text1", msg_type="String")

# Define a model client (working with Ollama in this case)
# OllamaModel is a generic wrapper for all Ollama models
qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
qwen_client = OllamaClient(qwen_vl, port=MODELS_PORT)

# Define a VLM component (A component represents a node with a particular functionality)
vlm = VLM(
    inputs=[text0, image0],
    outputs=[text1],
    model_client=qwen_client,
    trigger=text0,
    component_name="vqa"
)
# Additional prompt settings
vlm.set_topic_prompt(text0, template="""You are an amazing and funny robot.
Answer the following about this image: {{ text0 }}"""
)

# Launch the component
launcher = Launcher()
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(inputs=[text0], outputs=[text1, image0])  # <-- specify UI
launcher.add_pkg(components=[vlm])
launcher.bringup()
