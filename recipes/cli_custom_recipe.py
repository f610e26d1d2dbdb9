"""The custom recipe of getting-started/cli.md ("Writing Custom Recipes": recipe.py).

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/cli_custom_recipe.py
    emos topic pub /text0 String '{"data": "What do you see?"}'
    emos topic echo /text1

The spec's code with its imports changed, the Ollama client pointed at `emos serve models`
(EMOS_MODELS_PORT), and ``component_name`` given to the VLM: the page leaves it out, but a
component needs a name (EmbodiedAgents' components take ``component_name`` as a required
keyword too, so the page's code stops there as written).
"""
import os

from emos import Launcher, Topic
from emos.actors.agents import VLM, OllamaClient, OllamaModel

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

text_in  = Topic(name="text0",     msg_type="String")
image_in = Topic(name="image_raw", msg_type="Image")
text_out = Topic(name="text1",     msg_type="String")

model  = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
client = OllamaClient(model, port=MODELS_PORT)

vlm = VLM(
    inputs=[text_in, image_in],
    outputs=[text_out],
    model_client=client,
    trigger=text_in,
    component_name="vlm",  # not on the page: see the docstring
)

launcher = Launcher()
launcher.add_pkg(components=[vlm])
launcher.bringup()
