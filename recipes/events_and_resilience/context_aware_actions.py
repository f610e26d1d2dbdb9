"""Context-aware actions (seed recipe): action arguments read from topics when the event fires.

    emos run recipes/events_and_resilience/context_aware_actions.py --duration 7

Semantic navigation: a location name arriving on ``/user_command`` (while the mapper is
HEALTHY) calls ``navigate_to_location(command_topic.msg.data)``: the name is injected at fire
time, looked up, and published as a goal on ``/clicked_point`` through ``emos topic pub`` (the
seed shelled out to ``ros2 topic pub``). Dynamic prompts: when something is detected,
``describe_detected_object(detections.msg.labels[0])`` builds the prompt from the first label.

Stand-ins: ``Operator`` says "kitchen" at 1 s and "garage" (not on the map) at 2 s; ``Planner``
logs the goals it receives; ``LocalMapper`` is healthy; ``Detector`` sees a chair from 1.5 s.
"""
import json
import logging
import os
import subprocess
import sys
import time

import numpy as np

from emos import Action, BaseComponent, BaseComponentConfig, ComponentStatus, Event, Launcher, Topic
from emos.msgs import Detections, String

WAYPOINTS = {
    "kitchen": {"x": 2.0, "y": 0.5},
    "reception": {"x": 0.0, "y": 0.0},
    "station_a": {"x": -1.5, "y": 2.0},
}

log = logging.getLogger("recipe")


def navigate_to_location(location_name: str):
    key = location_name.strip().lower()
    if key not in WAYPOINTS:
        log.warning("Unknown location: %s", key)
        return
    coords = WAYPOINTS[key]
    point = {"header": {"frame_id": "map"}, "point": {"x": coords["x"], "y": coords["y"], "z": 0.0}}
    log.info("navigating to %s at (%.1f, %.1f)", key, coords["x"], coords["y"])
    subprocess.run([sys.executable, "-m", "emos", "topic", "pub", "/clicked_point", "geometry_msgs/msg/PointStamped",
                    json.dumps(point), "--rate", "10", "--count", "3", "--run", os.environ["EMOS_RUN_ID"]],
                   check=True, capture_output=True, timeout=30)


def describe_detected_object(label: str):
    prompt = f"A {label} has been detected. Describe what you see."
    log.info("VLM prompt: %s", prompt)
    return prompt


command_topic = Topic(name="/user_command", msg_type="String")
goal_topic = Topic(name="/clicked_point", msg_type="PointStamped")
detections = Topic(name="/detections", msg_type="Detections")


class Operator(BaseComponent):
    SCRIPT = [(1.0, "kitchen"), (2.0, "garage")]

    def custom_on_activate(self):
        self.t0, self.said = time.monotonic(), 0

    def _execution_step(self):
        if self.said < len(self.SCRIPT) and time.monotonic() - self.t0 > self.SCRIPT[self.said][0]:
            self.publish(command_topic, String(data=self.SCRIPT[self.said][1]))
            self.said += 1
        self.health_status.set_healthy()


class Planner(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        if (msg.point.x, msg.point.y) != getattr(self, "last", None):
            self.last = (msg.point.x, msg.point.y)
            self.get_logger().info("[planner] new goal in %s: (%.1f, %.1f)", msg.header.frame_id, msg.point.x, msg.point.y)
        self.health_status.set_healthy()


class LocalMapper(BaseComponent):
    pass


class Detector(BaseComponent):
    def custom_on_activate(self):
        self.t0 = time.monotonic()

    def _execution_step(self):
        labels = ["chair", "table"] if time.monotonic() - self.t0 > 1.5 else []
        self.publish(detections, Detections(labels=labels, scores=np.ones(len(labels)), boxes=np.zeros((len(labels), 4))))
        self.health_status.set_healthy()


operator = Operator(component_name="operator", outputs=[command_topic], config=BaseComponentConfig(loop_rate=10.0))
planner = Planner(component_name="planner", inputs=[goal_topic], trigger=goal_topic)
mapper = LocalMapper(component_name="mapper", config=BaseComponentConfig(loop_rate=10.0))
detector = Detector(component_name="detector", outputs=[detections], config=BaseComponentConfig(loop_rate=10.0))

event_command_received = Event(event_condition=(command_topic & (mapper.status_topic.msg.status == ComponentStatus.STATUS_HEALTHY)))
action_process_command = Action(method=navigate_to_location, args=(command_topic.msg.data,))  # dynamic injection

event_object_detected = Event(detections.msg.labels.length() > 0, on_change=True, keep_event_delay=5)
action_describe = Action(method=describe_detected_object, args=(detections.msg.labels[0],))

events_actions = {event_command_received: action_process_command, event_object_detected: action_describe}

launcher = Launcher()
launcher.kompass(components=[operator, planner, mapper, detector], activate_all_components_on_start=True, multiprocessing=True,
                 events_actions=events_actions)
launcher.bringup()
