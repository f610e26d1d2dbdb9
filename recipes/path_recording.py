"""Path recording and replay: the spec's path-recording recipe, in the spec's map (the TurtleBot3 arena).

    emos run recipes/path_recording.py

The spec's code with its imports and its simulator lines changed (the Simulator stands in for
the robot: ``/cmd_vel`` in, ``/odometry/filtered`` out). The Planner offers three services, and
the web UI (open the link the run prints; docs/ui.md) shows each as a form under Inputs:

* ``planner/save_plan_to_file`` (``PathFromToFile``: ``file_location``, ``file_name``): the
  current plan, or the recorded path while recording (saving stops the recording), as CSV ``x,y,yaw``;
* ``planner/load_plan_from_file`` (``PathFromToFile``): publishes the file as the global plan,
  and the Controller follows it;
* ``planner/start_path_recording`` (``StartPathRecording``: ``recording_time_step``): records
  the robot's location every step until the next save.

Goals for the planner (Option A of the page): ``emos topic pub /goal PointStamped
'{"point": {"x": 1.2, "y": 3.3}}'``. The services from Python (any process of the run)::

    save_path_srv.call(file_location="/tmp/", file_name="computed_path.csv")

and from a terminal (``ros2 service call`` of a ROS 2 system)::

    emos service call planner start_path_recording '{"recording_time_step": 0.1}'
    emos service call planner save_plan_to_file '{"file_location": "/tmp/", "file_name": "recorded_path.csv"}'
"""
import os

import numpy as np

from emos import Launcher, ServiceClientConfig, Topic
from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components import (
    Controller,
    DriveManager,
    DriveManagerConfig,
    MapServer,
    MapServerConfig,
    Planner,
    PlannerConfig,
    TopicsKeys,
)
from emos.actors.nav.components.interfaces import PathFromToFile, StartPathRecording
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.packages import get_package_share_directory


def run_path_recorder():
    kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")

    # 1. Robot Configuration
    my_robot = RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE,
        geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.1, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
    )

    # 2. Configure Components
    planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0))
    planner.run_type = "Timed"

    controller = Controller(component_name="controller")
    controller.algorithm = ControllersID.PURE_PURSUIT
    controller.direct_sensor = True  # Use direct sensor for simple obstacle checks

    driver = DriveManager(
        component_name="drive_manager",
        config=DriveManagerConfig(critical_zone_distance=0.05)
    )

    # Handle message types (Twist vs TwistStamped)
    cmd_msg_type = "TwistStamped" if os.environ.get("ROS_DISTRO") in ["rolling", "jazzy", "kilted"] else "Twist"
    driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))

    map_server = MapServer(
        component_name="global_map_server",
        config=MapServerConfig(
            map_file_path=os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml"),
            grid_resolution=0.5
        ),
    )

    # 3. Define Services for UI Interaction
    save_path_srv = ServiceClientConfig(
        name=f"{planner.node_name}/save_plan_to_file", srv_type=PathFromToFile
    )
    load_path_srv = ServiceClientConfig(
        name=f"{planner.node_name}/load_plan_from_file", srv_type=PathFromToFile
    )
    start_path_recording = ServiceClientConfig(
        name=f"{planner.node_name}/start_path_recording", srv_type=StartPathRecording
    )

    # 4. Launch
    launcher = Launcher()
    launcher.kompass(
        components=[map_server, planner, driver, controller],
        multiprocessing=True,
    )

    odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
    launcher.inputs(location=odom_topic)
    launcher.robot = my_robot
    launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")

    # The simulated robot (in place of the spec's external simulator): /cmd_vel in, odometry out
    # (the arena is built from the MapServer's map; the robot starts where Webots starts it)
    sim = Simulator("sim", config=SimulatorConfig(world=map_server.config.map_file_path, spawn=(0.0, 0.0, 0.0)))
    sim.inputs(command=Topic(name="/cmd_vel", msg_type=cmd_msg_type))
    sim.outputs(odom=odom_topic)
    launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)

    # 5. Enable UI with path services exposed as inputs
    launcher.enable_ui(
        inputs=[save_path_srv, load_path_srv, start_path_recording],
        outputs=[
            map_server.get_out_topic(TopicsKeys.GLOBAL_MAP),
            odom_topic,
            planner.get_out_topic(TopicsKeys.GLOBAL_PLAN),
        ],
    )

    launcher.bringup()


if __name__ == "__main__":
    run_path_recorder()
