"""Simulation quick start, Gazebo flavour: the spec's navigation stack and TurtleBot3 Waffle Pi in
the spec's house map.

    emos run recipes/nav_quick_start_gz.py
    # then, from another terminal, send a goal (x, y in metres, map frame), e.g. the right wing:
    emos topic pub /goal PointStamped '{"header": {"frame_id": "map"}, "point": {"x": 4.5, "y": 1.5}}'
    emos topic echo /reached_end

The spec's recipe runs against Gazebo's TurtleBot3 house and loads ``turtlebot3_gazebo_house.yaml``
from the ``kompass_sim`` share directory; here the ``Simulator`` component (pybullet, headless)
is the robot and builds the house from that same map, spawning the robot where kompass_sim
does, at (0.1, 0.2). Differences from the spec's code, and why:
* the Twist/TwistStamped switch on ``ROS_DISTRO`` is gone: there is no ROS distribution, and the
  Simulator takes ``Twist``;
* the frames are ``odom="map"``: the Simulator's odometry is already in the map frame (Gazebo's
  setup runs a localization node for the ``map -> odom`` transform);
* the Simulator lines (``sim`` and ``add_pkg``) stand in for launching Gazebo.
As in the spec, the web UI shows the map, the plan and the robot: open the link the run prints
(docs/ui.md) and click a goal on the map.
"""
import os

import numpy as np

from emos import Launcher, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, MapConfig, RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import (
    Controller,
    DriveManager,
    DriveManagerConfig,
    LocalMapper,
    LocalMapperConfig,
    MapServer,
    MapServerConfig,
    Planner,
    PlannerConfig,
    TopicsKeys,
)
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.packages import get_package_share_directory

kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")

# Setup your robot configuration (Turtlebot3 Waffle Pi)
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.BOX,  # Waffle Pi is rectangular
    geometry_params=np.array([0.3, 0.3, 0.2]),  # Length, Width, Height
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.26, max_acc=1.0, max_decel=1.0),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=1.8, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# Configure the Global Planner
planner_config = PlannerConfig(loop_rate=1.0)
planner = Planner(component_name="planner", config=planner_config)
planner.run_type = "Timed"

# Configure the motion controller
controller = Controller(component_name="controller")
controller.algorithm = ControllersID.PURE_PURSUIT
controller.direct_sensor = False  # Get local perception from a "map" instead (from the local mapper)

# Configure the Drive Manager (direct commands sent to the robot)
driver_config = DriveManagerConfig(critical_zone_distance=0.05, critical_zone_angle=90.0, slowdown_zone_distance=0.3)
driver = DriveManager(component_name="drive_manager", config=driver_config)
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))

# Configure a Local Mapper
local_mapper_config = LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05))
local_mapper = LocalMapper(component_name="mapper", config=local_mapper_config)

# Configure the global Map Server
# Note: We use the 'house' map to match the Gazebo world
map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_gazebo_house.yaml")
map_server_config = MapServerConfig(loop_rate=1.0, map_file_path=map_file, grid_resolution=0.5, pc_publish_row=False)
map_server = MapServer(component_name="global_map_server", config=map_server_config)

# The simulated robot in the house built from the same map (instead of Gazebo), where kompass_sim spawns it
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world=map_file, spawn=(0.1, 0.2, 0.0)))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom_topic)

# Setup the launcher
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, controller, planner, driver, local_mapper], multiprocessing=True)

# Get odom from the simulator for all components
launcher.inputs(location=odom_topic)

# Set the robot config and frames
launcher.robot = my_robot
launcher.frames = RobotFrames(world="map", odom="map", scan="base_scan")

# Enable the UI. Outputs: Static Map, Global Plan, Robot Odometry
launcher.enable_ui(
    outputs=[
        map_server.get_out_topic(TopicsKeys.GLOBAL_MAP),
        odom_topic,
        planner.get_out_topic(TopicsKeys.GLOBAL_PLAN),
    ],
)

# Run the Recipe
launcher.bringup()
