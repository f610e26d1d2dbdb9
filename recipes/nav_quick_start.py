"""Simulation quick start: the spec's navigation stack driving the simulated robot in the spec's map.

    emos run recipes/nav_quick_start.py
    # then, from another terminal, send a goal (x, y in metres, map frame):
    emos topic pub /goal PointStamped '{"header": {"frame_id": "map"}, "point": {"x": 1.2, "y": 3.3}}'
    emos topic echo /reached_end

The spec's recipe runs against Webots and loads ``turtlebot3_webots.yaml`` from the
``kompass_sim`` share directory; here the ``Simulator`` component (pybullet, headless) is the
robot and builds the arena from that same map, so the MapServer's map and the walls agree.
As in the spec, the web UI shows the map, the plan and the robot: open the link the run prints
(docs/ui.md). ``emos topic echo /odometry/filtered`` and ``emos status`` show them too.
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

# Setup your robot configuration
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
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
map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")
map_server_config = MapServerConfig(loop_rate=1.0, map_file_path=map_file, grid_resolution=0.5, pc_publish_row=False)
map_server = MapServer(component_name="global_map_server", config=map_server_config)

# The simulated robot in the arena built from the same map (instead of Webots), where Webots starts it
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world=map_file, spawn=(0.0, 0.0, 0.0)))
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom_topic)

# Setup the launcher
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, controller, planner, driver, local_mapper], multiprocessing=True)

# Get odom from the simulator for all components
launcher.inputs(location=odom_topic)

# Set the robot config for all components (and the simulated robot)
launcher.robot = my_robot
launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")

# Enable the web UI: the map, the robot and its plan in a browser
launcher.enable_ui(
    outputs=[
        map_server.get_out_topic(TopicsKeys.GLOBAL_MAP),
        odom_topic,
        planner.get_out_topic(TopicsKeys.GLOBAL_PLAN),
    ],
)

# Run the Recipe
launcher.bringup()
