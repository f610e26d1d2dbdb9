"""Motion testing: the MotionServer's circle test on the simulated robot, through the DriveManager.

    emos run recipes/motion_testing.py
    emos topic pub /run_tests Bool '{"data": true}'      # start the tests (or from the web UI)

The MotionServer sends the test commands on its default ``robot_command`` topic, ``/control``:
the DriveManager's default ``command`` input. The DriveManager's output (``/cmd_vel``) goes to
the robot and is what the MotionServer records (its ``command`` input), with the odometry as
the measured response. The circle test is the spec's sequence of three 10 s circles at half the
robot's limits (forward, inverse, backward), then the robot stops. Each test leaves a CSV and
a PNG (commanded vs measured velocities, driven path) in ``tests_folder``, named by the test
(``motion_server_circle_forward_<time>.csv``, ...). As in the spec, the web UI (open the link
the run prints; docs/ui.md) starts the tests and shows the map and the robot.
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
from emos.packages import get_package_share_directory


def run_motion_test():
    kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")

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

    # 4. Wiring, as in the spec: the driver publishes the final command; the MotionServer records
    # that same topic. Its tests go out on its default output, /control, the driver's command input.
    cmd_topic = Topic(name="/cmd_vel", msg_type="Twist")
    driver.outputs(robot_command=cmd_topic)
    motion_server.inputs(command=cmd_topic)

    # 5. Context (Map Server: the spec's map of the TurtleBot3 arena) and the simulated robot in the
    # arena built from that map, spawned where the three circles stay clear of the furniture
    map_server = MapServer(
        component_name="global_map_server",
        config=MapServerConfig(map_file_path=os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml"), grid_resolution=0.5),
    )
    odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
    sim = Simulator("sim", config=SimulatorConfig(world=map_server.config.map_file_path, spawn=(1.0, -2.9, np.pi / 2)))
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


if __name__ == "__main__":
    run_motion_test()
