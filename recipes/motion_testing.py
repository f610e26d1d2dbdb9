"""Motion testing: the MotionServer's circle test on the simulated robot, through the DriveManager.

    emos run recipes/motion_testing.py
    emos topic pub /run_tests Bool '{"data": true}'      # start the tests (or from the web UI)

The MotionServer sends the test commands (``robot_command`` -> the DriveManager's ``command``
input), the DriveManager's output goes to the robot and is what the MotionServer records
(its ``command`` input), with the odometry as the measured response. Each test leaves a CSV
and a PNG (commanded vs measured velocities, driven path) in ``tests_folder``. As in the spec,
the web UI (open the link the run prints; docs/ui.md) starts the tests and shows the map and
the robot.
"""
import os

import numpy as np

from emos import Launcher, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import (
    DriveManager,
    DriveManagerConfig,
    MapServer,
    MapServerConfig,
    MotionServer,
    MotionServerConfig,
    TopicsKeys,
)
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.data import HOUSE_MAP

# 1. Robot
my_robot = RobotConfig(
    model_type=RobotType.DIFFERENTIAL_DRIVE,
    geometry_type=RobotGeometry.Type.CYLINDER,
    geometry_params=np.array([0.1, 0.3]),
    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
    ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
)

# 2. Motion Server: circle tests of 10 s, triggered by /run_tests
motion_config = MotionServerConfig(
    test_period=10.0,
    run_circle_test=True,
    run_step_test=False,
    tests_folder=os.path.expanduser("~/.emos/tests"),  # where the CSVs and plots go
)
motion_server = MotionServer(component_name="motion_server", config=motion_config)
motion_server.run_type = "Event"  # wait for a trigger to start

# 3. Drive Manager: the safety layer between the MotionServer and the robot
driver = DriveManager(component_name="drive_manager", config=DriveManagerConfig(critical_zone_distance=0.05))

# 4. Wiring: the MotionServer's commands go through the driver; the driver's output is recorded
cmd_topic = Topic(name="/cmd_vel", msg_type="Twist")
driver.outputs(robot_command=cmd_topic)
motion_server.inputs(command=cmd_topic)
motion_server.outputs(robot_command=Topic(name="/control", msg_type="Twist"))  # the driver's command input

# 5. Context (Map Server) and the simulated robot, spawned in the open part of a room
map_server = MapServer(
    component_name="global_map_server",
    config=MapServerConfig(map_file_path=str(HOUSE_MAP), grid_resolution=0.5),
)
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=(2.5, 2.0, 0.0)))
sim.inputs(command=cmd_topic)
sim.outputs(odom=odom_topic)

# 6. Launch
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, driver, motion_server], multiprocessing=True)
launcher.inputs(location=odom_topic)  # the response we record
launcher.robot = my_robot
launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")
# 7. Enable the web UI: the RUN_TESTS input as a button, the map and the robot
launcher.enable_ui(
    inputs=[motion_server.get_in_topic(TopicsKeys.RUN_TESTS)],
    outputs=[map_server.get_out_topic(TopicsKeys.GLOBAL_MAP), odom_topic],
)
launcher.bringup()
