"""Vision tracking with RGB: the spec's vision-tracking-rgb recipe, ported to the simulator.

    emos run recipes/vision_tracking_rgb.py          # or: python recipes/vision_tracking_rgb.py
    # then, as on the spec's page ("Trigger the Following Action"), from another terminal:
    emos action send_goal my_controller track_vision_target '{"label": "person"}'   # Ctrl-C cancels

A ``Vision`` component detects people in the camera frames and the ``Controller``'s
``VisionRGBFollower`` keeps the person centred in the image and at the distance it had when
tracking started (the box size), through the ``DriveManager``. The ``Simulator`` (pybullet,
headless) stands in for the robot and its camera: a person walks to and fro across the room in
front of the robot (a textured figure, see ``emos.actors.sim.person``).

Differences from the spec's recipe, and why:
* the detector is the Vision component's on-board one (``enable_local_classifier=True``: the
  OpenCV HOG people detector that ships with OpenCV) instead of an mmdetection model served by
  RoboML; ``emos serve models`` with a ``VisionModel`` client works the same way;
* ``include_image=True`` makes the frame travel with the detections: the follower needs the
  image size and a ``Detections`` message carries it only with its image;
* the follower's ``rotation_gain`` is 3 instead of its default 1 (see below);
* ``enable_visualization=True`` publishes the annotated frames on ``/detection_component/visualization``
  (an Image topic for the web UI or Foxglove) instead of the original's pop-up window;
* the page's ``ros2 action send_goal /my_controller/track_vision_target ...`` is
  ``emos action send_goal my_controller track_vision_target '{"label": "person"}'`` (above).
"""
import numpy as np

from emos import Launcher, Topic
from emos.actors.agents import Vision, VisionConfig
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, ControllerConfig, DriveManager
from emos.actors.nav.controllers import VisionRGBFollowerConfig
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person

# The simulated scene: the robot in the house's first room, a person pacing across the room
# 2.4 m ahead, to either side further than the camera sees (+-0.53 rad against a half field of
# view of 0.66 rad less the person's width): the robot keeps it in view only by turning.
ROBOT_SPAWN = (1.0, 2.0, 0.0)
PERSON_PATH = ((3.4, 0.6), (3.4, 3.4))
PERSON_SPEED = 0.2  # m/s

# RGB camera input topic is set to the compressed image topic
image0 = Topic(name="/image_raw/compressed", msg_type="CompressedImage")

# Select the output topics: detections and trackings
detections_topic = Topic(name="detections", msg_type="Detections")
trackings_topic = Topic(name="trackings", msg_type="Trackings")

# Select the vision component configuration (on-board people detector, see the module doc)
detection_config = VisionConfig(threshold=0.5, enable_visualization=True, enable_local_classifier=True, include_image=True)

vision = Vision(
    inputs=[image0],
    outputs=[detections_topic, trackings_topic],
    trigger=image0,
    config=detection_config,
    component_name="detection_component",
)

# Setup your robot configuration
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.2, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# Set the controller component configuration
config = ControllerConfig(loop_rate=10.0, ctrl_publish_type="Sequence", control_time_step=0.3)

# Init the controller
controller = Controller(component_name="my_controller", config=config)
controller.inputs(vision_tracking=detections_topic)

# Set the vision follower configuration
# rotation_gain=3 (default 1): with the spec's 0.2 rad/s limit, gain 1 turns at 0.2 rad/s only for a
# box at the image border, too slow to keep a person crossing 2.4 m ahead in view.
vision_follower_config = VisionRGBFollowerConfig(
    control_horizon=3, enable_search=False, target_search_pause=6, tolerance=0.2, rotation_gain=3.0)
controller.algorithms_config = vision_follower_config

# Init the drive manager with the default parameters (its commands go to the simulated base)
driver = DriveManager(component_name="my_driver")
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))

# The simulated robot, camera and walking person (instead of a real robot and usb_cam)
sim = Simulator("sim", config=SimulatorConfig(
    world="house", spawn=ROBOT_SPAWN,
    moving_obstacles=[Person(waypoints=np.array(PERSON_PATH), speed=PERSON_SPEED, mode="pingpong")]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(camera=image0)

launcher = Launcher()
launcher.add_pkg(components=[vision, sim], ros_log_level="warn")
launcher.kompass(components=[controller, driver])
# Set the robot config for all components
launcher.robot = my_robot

# Start all the components
launcher.bringup()
