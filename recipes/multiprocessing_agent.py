"""Multiprocessing (resilience recipe): the complete agent of complete_agent.py with every
component in its own process, and a launcher-wide fallback that restarts a failing component
every 10 s. As in the spec, its detector is a vision model on the model server (RoboML over
RESP) instead of the on-board classifier.

    emos serve models --script recipes/models/responder.yaml --resp-port 6379 &
    emos run recipes/multiprocessing_agent.py

Inputs: ``audio0`` (or ``question`` as text), ``image_raw``, ``odom``, ``map``.
Outputs: ``answer`` (text, and speech on the speakers when there are any), ``goal_point``.
"""
import os

# The complete agent's graph, built by the recipe beside this one (imported, it does not start).
from complete_agent import detections_topic, goto, image0, introspector, llm, map, mllm, router, speech_to_text, text_to_speech

from emos import Launcher
from emos.actors.agents import RoboMLRESPClient, Vision, VisionConfig, VisionModel

MODELS_RESP_PORT = int(os.environ.get("EMOS_MODELS_RESP_PORT", "6379"))

object_detection_model = VisionModel(name="object_detection", checkpoint="dino-4scale_r50_8xb2-12e_coco")
detection_client = RoboMLRESPClient(object_detection_model, port=MODELS_RESP_PORT)
detection_config = VisionConfig(threshold=0.5)
vision = Vision(
    inputs=[image0],
    outputs=[detections_topic],
    trigger=image0,
    config=detection_config,
    model_client=detection_client,
    component_name="object_detection",
)

launcher = Launcher()
launcher.add_pkg(
    components=[mllm, llm, goto, introspector, map, router, speech_to_text, text_to_speech, vision],
    package_name="automatika_embodied_agents",  # accepted for the port; EMOS needs no package
    multiprocessing=True,
)
# Launcher-wide fallback: restart a failing component, every 10 s at most (0.1 Hz).
launcher.on_fail(action_name="restart")
launcher.fallback_rate = 1 / 10
launcher.bringup()
