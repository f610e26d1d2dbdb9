"""Event-driven cognition (seed recipe): a cheap detector wakes an expensive describer.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/events_and_resilience/event_driven_cognition.py --duration 30

The spec's recipe on real components: the ``Vision`` component ``eye_detector`` runs its
on-board people detector (``enable_local_classifier=True``: OpenCV's HOG detector) on every
camera frame; the ``VLM`` ``visual_describer`` has no topic trigger: its trigger is
``event_person_detected`` (``labels`` contains "person", ``on_change=True``,
``keep_event_delay=5``), so the Monitor runs one VLM step when a person *appears* (at most once
per 5 s), and the VLM sends the latest frame with the fixed prompt to its model server.

What stands in for what:
* the ``Simulator`` (pybullet, headless) is the robot's camera: ``world="house_person"``, the
  demo house with a person walking across the robot's view, out through the doorway behind the
  wall (out of sight from ~7 s of simulated time) and back (in sight again from ~12 s), over and
  over; its camera publishes on the spec's ``/image_raw``;
* ``Narrator`` (below) only reports: when the detector starts and stops seeing a person, how
  many frames with a person it saw, and each description, so a headless run shows what happened;
* ``emos serve models`` is Ollama: ``qwen2.5vl:7b`` there is the scripted responder of
  ``recipes/models/responder.yaml`` (this machine cannot run a 7B VLM), which answers the
  prompt without looking at the picture. The detector, the event and the VLM component, its
  client and its request with the frame are the real ones.

Differences from the spec's code: the imports, the model client's port (``EMOS_MODELS_PORT``),
and the Simulator. The spec's ``launcher.enable_ui(...)`` line runs when ``EMOS_UI=1`` (the UI
serves http://127.0.0.1:5001; a headless run or a test does not need it).
"""
import os

from emos import BaseComponent, Event, FixedInput, Launcher, Topic
from emos.actors.agents import VLM, OllamaClient, OllamaModel, Vision, VisionConfig
from emos.actors.sim import Simulator, SimulatorConfig

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))  # `emos serve models` (Ollama API)

# Define Topics
camera_image = Topic(name="/image_raw", msg_type="Image")
detections = Topic(name="/detections", msg_type="Detections")  # Output of Vision
description_output = Topic(name="/description", msg_type="String")  # Output of VLM

# Setup the Vision Component (The Trigger)
# We use a lower threshold to ensure we catch people easily and we use a small local model
vision_config = VisionConfig(threshold=0.6, enable_local_classifier=True)
vision_detector = Vision(
    inputs=[camera_image],
    outputs=[detections],
    trigger=camera_image,  # Runs on every frame
    config=vision_config,
    component_name="eye_detector",
)

# Define the Event
# It triggers ONLY if the "labels" list of the detections contains "person" after not
# containing one, and at most once every 5 seconds.
event_person_detected = Event(
    detections.msg.labels.contains_any(["person"]),
    on_change=True,  # Trigger only when a change has occurred to stop repeat triggering
    keep_event_delay=5,  # A delay in seconds
)

# Setup the VLM Component (The Responder): it does NOT run continuously, it waits for the event.
qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:7b")
ollama_client = OllamaClient(model=qwen_vl, port=MODELS_PORT)

# A fixed prompt, injected whenever the component runs.
fixed_prompt = FixedInput(
    name="prompt",
    msg_type="String",
    fixed="A person has been detected. Describe their appearance briefly.",
)

visual_describer = VLM(
    inputs=[fixed_prompt, camera_image],  # Takes the fixed prompt + current image
    outputs=[description_output],
    model_client=ollama_client,
    trigger=event_person_detected,  # CRITICAL: Only runs when the event fires
    component_name="visual_describer",
)

# --- The robot's camera: the simulated house with a walking person (see the module doc) ---
sim = Simulator("sim", config=SimulatorConfig(world="house_person"))
sim.outputs(camera=camera_image)



class Narrator(BaseComponent):
    """Prints the detector's person edges and every description (it only reads topics)."""

    def custom_on_activate(self):
        self.in_view, self.frames_with_person, self.descriptions = False, 0, 0

    def _execution_step(self, msg=None, topic=None):
        self.health_status.set_healthy()
        if topic is not None and topic.name == description_output.name:
            self.descriptions += 1
            print(f"[narrator] description #{self.descriptions} (after {self.frames_with_person} frames with a person): "
                  f"{msg.data!r}", flush=True)
        elif topic is not None:
            seen = "person" in list(msg.labels)
            self.frames_with_person += seen
            if seen != self.in_view:
                self.in_view = seen
                print(f"[narrator] eye_detector: a person {'came into' if seen else 'left'} view", flush=True)


narrator = Narrator(component_name="narrator", inputs=[detections, description_output],
                    trigger=[detections, description_output])

# Launch
launcher = Launcher()
if os.environ.get("EMOS_UI") == "1":
    launcher.enable_ui(outputs=[camera_image, detections, description_output])
launcher.add_pkg(
    components=[vision_detector, visual_describer],
    multiprocessing=True,
    package_name="automatika_embodied_agents",
)
launcher.add_pkg(components=[sim, narrator], multiprocessing=True, package_name="simulation")
launcher.bringup()
