"""Event-driven cognition (seed recipe): a cheap detector wakes an expensive describer.

    emos run recipes/events_and_resilience/event_driven_cognition.py --duration 8

``eye_detector`` runs on every camera frame; ``visual_describer`` has no topic trigger: its
trigger is ``event_person_detected`` (``labels`` contains "person", ``on_change=True``,
``keep_event_delay=5``), so it runs one step when a person *appears*, at most once per 5 s,
instead of on every frame.

Stand-ins: the model is not the point here, so ``Camera`` renders a scripted scene (a person
walks in at 0.8 s and out at 1.6 s: described; back at 2.2 s: not described, within 5 s of the
last description; back at 6 s to stay: described), ``Vision`` "detects" by reading the
scene's colour code from the frame, and ``VLM`` describes the latest frame from its pixels with
a fixed prompt. The event, the trigger and the launcher are the real API.
"""
import time

import numpy as np

from emos import BaseComponent, Event, Launcher, Topic
from emos.msgs import Detections, Image, String

camera_image = Topic(name="/image_raw", msg_type="Image")
detections = Topic(name="/detections", msg_type="Detections")
description_output = Topic(name="/description", msg_type="String")

PERSON_VISIBLE = [(0.8, 1.6), (2.2, 3.0), (6.0, 1e9)]  # seconds after the camera starts


class Camera(BaseComponent):
    """Renders the scene: red pixels where a person stands."""

    def custom_on_activate(self):
        self.t0 = time.monotonic()

    def _execution_step(self):
        t = time.monotonic() - self.t0
        frame = np.full((48, 64, 3), 90, np.uint8)
        if any(a <= t < b for a, b in PERSON_VISIBLE):
            frame[10:40, 20:34] = (200, 30, 30)
        self.publish(camera_image, Image.from_numpy(frame, "rgb8"))
        self.health_status.set_healthy()


class Vision(BaseComponent):
    """Stand-in detector: a red blob is a person."""

    def _execution_step(self, msg=None, topic=None):
        frame = msg.to_numpy()
        red = (frame[..., 0] > 150) & (frame[..., 1] < 80)
        labels = ["person"] if red.sum() > 50 else []
        boxes = np.array([[20.0, 10.0, 34.0, 40.0]]) if labels else np.zeros((0, 4))
        self.publish(detections, Detections(labels=labels, scores=np.ones(len(labels)), boxes=boxes))
        self.health_status.set_healthy()


class VLM(BaseComponent):
    """Stand-in describer: answers its fixed prompt from the latest frame's pixels."""

    def __init__(self, prompt: str, **kwargs):
        super().__init__(**kwargs)
        self.prompt = prompt

    def _execution_step(self, **_):
        frame = self.get_input(camera_image)
        if frame is None:
            self.health_status.set_fail_system(topic_names=[camera_image.name])
            return
        pixels = frame.to_numpy().reshape(-1, 3)
        share = float(((pixels[:, 0] > 150) & (pixels[:, 1] < 80)).mean())
        text = f"{self.prompt} -> a person in red clothes fills {share:.0%} of the view"
        self.publish(description_output, String(data=text))
        self.get_logger().info("[visual_describer] %s", text)
        self.health_status.set_healthy()


camera = Camera(component_name="camera", outputs=[camera_image])
camera.config.loop_rate = 15.0

vision_detector = Vision(inputs=[camera_image], outputs=[detections], trigger=camera_image, component_name="eye_detector")

event_person_detected = Event(
    detections.msg.labels.contains_any(["person"]),
    on_change=True,  # only when a person appears
    keep_event_delay=5,  # and at most once every 5 s
)

visual_describer = VLM(
    prompt="A person has been detected. Describe their appearance briefly.",
    inputs=[camera_image],
    outputs=[description_output],
    trigger=event_person_detected,  # runs only when the event fires
    component_name="visual_describer",
)

launcher = Launcher()
launcher.add_pkg(components=[camera, vision_detector, visual_describer], multiprocessing=True, package_name="automatika_embodied_agents")
launcher.bringup()
