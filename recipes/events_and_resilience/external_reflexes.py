"""External reflexes: the spec's external-reflexes recipe, on the real Vision and Controller.

    emos run recipes/events_and_resilience/external_reflexes.py --duration 40

The robot idles in the first room of the simulated house. A person comes from the far end of
the room and crosses it in front of the robot, to its right. The ``Vision`` component (on-board people
detector) reports "person"; ``event_person_detected`` (``on_change=True``: when "person" first
appears in the labels) runs two actions in order: ``update_parameter`` switches the
``Controller``'s ``algorithm`` to ``VisionRGBDFollower``, then ``send_component_action_server_goal``
sends the Controller's ``track_vision_target`` action a ``TrackVisionTarget`` goal with the
label "person"; the robot turns and drives to keep the person ahead at 2.4 m.

What is real: Vision, Controller, DriveManager, LocalMapper, the Monitor running the event, and
the ``Simulator`` (pybullet, headless) standing in for the robot and its RealSense: the RGBD
stream on ``/camera/rgbd``, the depth camera's intrinsics, odometry, lidar, and a walking
person (``PERSON_PATH``: textured figure on a collision cylinder). Nothing is stood in.

Differences from the spec's code, and why:
* the Controller starts with ``DWA`` (the spec sets ``VisionRGBDFollower`` before the event, so
  the event's switch changes nothing, see the errata): with no plan it holds the robot still
  until the reflex switches it;
* the detector is the Vision component's on-board one (OpenCV's HOG people detector) with a
  400 x 300 picture of 70 deg vertical field of view (HOG needs the whole figure at >= 128 px),
  and the follower keeps ``target_distance=2.4`` m and knows the camera's mount on the robot, as
  in ``recipes/vision_tracking_depth.py``;
* the Simulator's topics replace the RealSense driver's (same names), its commands are Twist;
* ``add_pkg``'s ROS package and executable names are kept but mean nothing here.
"""
import numpy as np

from emos import Event, Launcher, Topic
from emos.actions import send_component_action_server_goal, update_parameter
from emos.actors.agents import Vision, VisionConfig
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, ControllerConfig, DriveManager, LocalMapper
from emos.actors.nav.components.interfaces import TrackVisionTarget
from emos.actors.nav.controllers import ControllersID, VisionRGBDFollowerConfig
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person

ROBOT_SPAWN = (1.0, 2.0, 0.0)  # x, y, yaw in the house's first room, facing +x
# From the far end of the room (too far for the detector, and seen edge-on as they walk towards
# the robot), then across the room 2.4 m ahead, to the robot's right, where the person stops.
PERSON_PATH = ((4.4, 3.4), (3.4, 3.4), (3.4, 1.0))
PERSON_SPEED = 0.25  # m/s

# --- Vision Detector ---
image0 = Topic(name="/camera/rgbd", msg_type="RGBD")
detections_topic = Topic(name="detections", msg_type="Detections")

detection_config = VisionConfig(threshold=0.5, enable_local_classifier=True, input_width=400, input_height=300)
vision = Vision(
    inputs=[image0],
    outputs=[detections_topic],
    trigger=image0,
    config=detection_config,
    component_name="detection_component",
)

# --- Robot Configuration ---
my_robot = RobotConfig(
    model_type=RobotType.ACKERMANN,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=3.0, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=6.0, max_decel=10.0, max_steer=np.pi / 3),
)

# --- Navigation Components ---
depth_cam_info_topic = Topic(name="/camera/aligned_depth_to_color/camera_info", msg_type="CameraInfo")

config = ControllerConfig(ctrl_publish_type="Parallel")
controller = Controller(component_name="controller", config=config)
controller.inputs(vision_detections=detections_topic, depth_camera_info=depth_cam_info_topic)
controller.algorithm = ControllersID.DWA  # errata: the spec sets "VisionRGBDFollower" here (see the docstring)
controller.algorithms_config = VisionRGBDFollowerConfig(target_distance=2.4, camera_position_to_robot=np.array([0.2, 0.0, 0.4]))
controller.direct_sensor = False

driver = DriveManager(component_name="driver")
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
mapper = LocalMapper(component_name="local_mapper")

# --- Event: Person Detected ---
event_person_detected = Event(
    event_condition=detections_topic.msg.labels.contains("person"),
    on_change=True,
)

# --- Actions: Switch Algorithm + Start Following ---
switch_algorithm_action = update_parameter(
    component=controller,
    param_name="algorithm",
    new_value="VisionRGBDFollower",
)

action_request_msg = TrackVisionTarget.Goal()
action_request_msg.label = "person"
action_start_person_following = send_component_action_server_goal(
    component=controller,
    request_msg=action_request_msg,
)

events_action = {
    event_person_detected: [switch_algorithm_action, action_start_person_following],
}

# --- The simulated robot, its RealSense and the walking person (instead of the real ones) ---
sim = Simulator("sim", config=SimulatorConfig(
    world="house", spawn=ROBOT_SPAWN, camera_width=400, camera_height=300, camera_vfov_deg=70.0,
    camera_rate=5.0,  # frames/s: as many as the detector takes (rendering costs the simulator ~0.1 s each)
    moving_obstacles=[Person(waypoints=np.array(PERSON_PATH), speed=PERSON_SPEED, mode="once")]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(rgbd=image0, depth_camera_info=depth_cam_info_topic)

# --- Launch ---
launcher = Launcher()
launcher.add_pkg(
    components=[vision],
    ros_log_level="warn",
    package_name="automatika_embodied_agents",
    executable_entry_point="executable",
    multiprocessing=True,
)
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(
    components=[controller, mapper, driver],
    events_actions=events_action,
)
launcher.robot = my_robot
launcher.bringup()
