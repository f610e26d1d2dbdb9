"""External reflexes (seed recipe): a person in view switches the controller to following.

    emos run recipes/events_and_resilience/external_reflexes.py --duration 6

``detection_component`` finds people in the camera stream; ``event_person_detected`` fires when
"person" first appears in its labels (``on_change=True``) and runs two actions in sequence:
``update_parameter`` switches the controller's ``algorithm`` to VisionRGBDFollower, then
``send_component_action_server_goal`` sends a tracking goal (label "person") to the controller's
action server.

Stand-ins: ``Camera`` (a scripted scene: a person appears at 1.5 s), ``Vision`` (a red blob is
a person), ``Controller`` (an ActionServer whose goal is ``TrackVisionTarget``: it logs the
algorithm it follows with and reports progress), ``DriveManager`` and ``LocalMapper`` (idle).
The robot configuration of the seed recipe belongs to the navigation stack and is left out.
"""
import time

import numpy as np
from attrs import define, field

from emos import BaseComponent, BaseComponentConfig, Event, Launcher, Topic
from emos.actions import send_component_action_server_goal, update_parameter
from emos.msgs import Detections, Image, message_type
from emos.msgs import fields as F

image0 = Topic(name="/camera/rgbd", msg_type="Image")
detections_topic = Topic(name="detections", msg_type="Detections")


@message_type("kompass_interfaces", name="TrackVisionTarget_Goal")
class TrackVisionTargetGoal:
    label: str = F.string()


@message_type("kompass_interfaces", name="TrackVisionTarget_Feedback")
class TrackVisionTargetFeedback:
    distance: float = F.float64()


@message_type("kompass_interfaces", name="TrackVisionTarget_Result")
class TrackVisionTargetResult:
    success: bool = F.boolean()


class Camera(BaseComponent):
    def custom_on_activate(self):
        self.t0 = time.monotonic()

    def _execution_step(self):
        frame = np.full((48, 64, 3), 90, np.uint8)
        if time.monotonic() - self.t0 > 1.5:
            frame[10:40, 20:34] = (200, 30, 30)
        self.publish(image0, Image.from_numpy(frame, "rgb8"))
        self.health_status.set_healthy()


class Vision(BaseComponent):
    def _execution_step(self, msg=None, topic=None):
        frame = msg.to_numpy()
        seen = int(((frame[..., 0] > 150) & (frame[..., 1] < 80)).sum()) > 50
        labels = ["person"] if seen else []
        self.publish(detections_topic, Detections(labels=labels, scores=np.ones(len(labels)), boxes=np.zeros((len(labels), 4))))
        self.health_status.set_healthy()


@define(kw_only=True)
class ControllerConfig(BaseComponentConfig):
    algorithm: str = field(default="DWA")
    ctrl_publish_type: str = field(default="Sequence")


class Controller(BaseComponent):
    main_action_type = (TrackVisionTargetGoal, TrackVisionTargetFeedback, TrackVisionTargetResult)

    def _main_action_callback(self, goal_handle):
        label = goal_handle.goal.label
        self.get_logger().info("[controller] following %r with %s", label, self.config.algorithm)
        for k in range(3):
            goal_handle.publish_feedback(TrackVisionTargetFeedback(distance=2.0 - 0.5 * k))
            time.sleep(0.05)
        return TrackVisionTargetResult(success=True)


class DriveManager(BaseComponent):
    pass


class LocalMapper(BaseComponent):
    pass


camera = Camera(component_name="camera", outputs=[image0])
camera.config.loop_rate = 15.0
vision = Vision(inputs=[image0], outputs=[detections_topic], trigger=image0, component_name="detection_component")

controller = Controller(component_name="controller", config=ControllerConfig(ctrl_publish_type="Parallel"), inputs=[detections_topic])
controller.run_type = "ActionServer"
driver = DriveManager(component_name="driver")
mapper = LocalMapper(component_name="local_mapper")

event_person_detected = Event(event_condition=detections_topic.msg.labels.contains("person"), on_change=True)

switch_algorithm_action = update_parameter(component=controller, param_name="algorithm", new_value="VisionRGBDFollower")
action_request_msg = TrackVisionTargetGoal()
action_request_msg.label = "person"
action_start_person_following = send_component_action_server_goal(component=controller, request_msg=action_request_msg)

events_action = {event_person_detected: [switch_algorithm_action, action_start_person_following]}

launcher = Launcher()
launcher.add_pkg(components=[camera, vision], ros_log_level="info", package_name="automatika_embodied_agents", multiprocessing=True)
launcher.kompass(components=[controller, mapper, driver], events_actions=events_action, multiprocessing=True)
launcher.bringup()
