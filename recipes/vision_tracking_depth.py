"""Vision tracking with depth: the spec's vision-tracking-depth recipe, ported to the simulator.

    emos run recipes/vision_tracking_depth.py        # or: python recipes/vision_tracking_depth.py
    # then, as on the spec's page, from another terminal:
    emos action send_goal controller track_vision_target '{"label": "person"}'   # Ctrl-C cancels

The ``Vision`` component detects people in the colour image of the ``RGBD`` stream (on-board
classifier, ``enable_local_classifier=True``: OpenCV's HOG people detector) and publishes the
detections with the stream's depth image attached. The ``Controller``'s ``VisionRGBDFollower``
back-projects the person's box through the depth image and the intrinsics of
``depth_camera_info`` to a point on the floor and drives an Ackermann robot to keep it ahead at
the distance it had when tracking started, through the ``DriveManager``; the ``LocalMapper``
gives the controller its obstacle grid. The ``Simulator`` (pybullet, headless) stands in for the
robot and its RealSense: a person walks to and fro across the room in front of the robot.

Differences from the spec's recipe, and why:
* the simulator's topics replace the RealSense driver's (same names for the RGBD stream and the
  depth camera info);
* the page's ``ros2 action send_goal .../track_vision_target ...`` is
  ``emos action send_goal controller track_vision_target '{"label": "person"}'`` (above);
* the simulator joins the Vision component's package (``add_pkg`` takes the page's ROS package
  and executable names, and needs neither: there is no ROS package);
* the follower keeps ``target_distance=2.4`` m and knows the camera's mount on the robot, and the
  simulated camera is 400 x 300 with a 70 deg vertical field of view: OpenCV's HOG detector
  needs the person's whole figure at >= 128 px, so closer (or in a smaller picture) it would
  lose the person.
"""
import numpy as np

from emos import Launcher, Topic
from emos.actors.agents import Vision, VisionConfig
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.components import Controller, ControllerConfig, DriveManager, LocalMapper
from emos.actors.nav.controllers import VisionRGBDFollowerConfig
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.person import Person

# The simulated scene: the robot in the house's first room, a person pacing across the room
# 2.4 m ahead, to either side further than the camera sees: the robot keeps it in view only by
# turning (an Ackermann robot turns while it rolls).
ROBOT_SPAWN = (1.0, 2.0, 0.0)
PERSON_PATH = ((3.4, 1.2), (3.4, 2.8))
PERSON_SPEED = 0.12  # m/s

image0 = Topic(name="/camera/rgbd", msg_type="RGBD")
detections_topic = Topic(name="detections", msg_type="Detections")

# The people detector sees the camera's full 400 x 300 frames (its default scales to 320 x 240)
detection_config = VisionConfig(threshold=0.5, enable_local_classifier=True, input_width=400, input_height=300)
vision = Vision(
    inputs=[image0],
    outputs=[detections_topic],
    trigger=image0,
    config=detection_config,
    component_name="detection_component",
)

# Setup your robot configuration
my_robot = RobotConfig(
    model_type=RobotType.ACKERMANN,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=3.0, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=6.0, max_decel=10.0, max_steer=np.pi / 3),
)

depth_cam_info_topic = Topic(name="/camera/aligned_depth_to_color/camera_info", msg_type="CameraInfo")

# Setup the controller
config = ControllerConfig(ctrl_publish_type="Parallel")
controller = Controller(component_name="controller", config=config)
controller.inputs(vision_detections=detections_topic, depth_camera_info=depth_cam_info_topic)
controller.algorithm = "VisionRGBDFollower"
# Keep 2.4 m (the person's whole figure stays in the picture: closer, the detector loses it) and
# say where the simulated camera sits on the robot (0.2 m ahead of the base, 0.4 m up).
controller.algorithms_config = VisionRGBDFollowerConfig(target_distance=2.4, camera_position_to_robot=np.array([0.2, 0.0, 0.4]))
controller.direct_sensor = False

# Add additional helper components (the driver's commands go to the simulated base)
driver = DriveManager(component_name="driver")
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))
mapper = LocalMapper(component_name="local_mapper")

# The simulated robot, RGBD camera and walking person (instead of a real robot and RealSense)
sim = Simulator("sim", config=SimulatorConfig(
    world="house", spawn=ROBOT_SPAWN, camera_width=400, camera_height=300, camera_vfov_deg=70.0,
    moving_obstacles=[Person(waypoints=np.array(PERSON_PATH), speed=PERSON_SPEED, mode="pingpong")]))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(rgbd=image0, depth_camera_info=depth_cam_info_topic)

# Bring it up with the launcher
launcher = Launcher()
launcher.add_pkg(components=[vision, sim], ros_log_level="warn",
                 package_name="automatika_embodied_agents",
                 executable_entry_point="executable",
                 multiprocessing=True)
launcher.kompass(components=[controller, mapper, driver])
# Set the robot config for all components
launcher.robot = my_robot
launcher.bringup()
