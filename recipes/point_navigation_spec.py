"""Point navigation as the spec's page gives it (navigation/point-navigation.md, "Complete Recipe
Code"): the stack in the TurtleBot3 Webots arena, goals clicked on the map in the web UI.

    emos run recipes/point_navigation_spec.py
    # open the link it prints and click on the map, or from another terminal:
    emos topic pub /goal PointStamped '{"header": {"frame_id": "map"}, "point": {"x": 1.5, "y": -3.2}}'

The page's code with its imports changed and its simulator lines added: the ``Simulator``
(pybullet, headless) builds the arena from the same map in place of Webots and is the robot
(``/cmd_vel`` in, ``/odometry/filtered`` out), and the command type is ``Twist`` (no ROS
distributions here). recipes/point_navigation.py is the same stack as a self-judging mission
(the main job: two goals, a summary and a plot, exit code 0 on success).
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


def kompass_bringup():
    kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")

    # 1. Robot Configuration
    my_robot = RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE,
        geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.1, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=0.4, max_acc=1.5, max_decel=2.5),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=0.4, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
    )

    # 2. Components
    planner = Planner(component_name="planner", config=PlannerConfig(loop_rate=1.0))
    planner.run_type = "Timed"

    controller = Controller(component_name="controller")
    controller.algorithm = ControllersID.PURE_PURSUIT
    controller.direct_sensor = False

    driver = DriveManager(
        component_name="drive_manager",
        config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.3)
    )

    # 3. Dynamic Command Type (no ROS distributions here: Twist)
    cmd_type = "Twist"
    driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type=cmd_type))

    # 4. Mapping
    local_mapper = LocalMapper(
        component_name="mapper",
        config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05))
    )

    map_server = MapServer(
        component_name="global_map_server",
        config=MapServerConfig(
            map_file_path=os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml"),
            grid_resolution=0.5
        )
    )

    # 5. Launch
    launcher = Launcher()
    launcher.kompass(
        components=[map_server, controller, planner, driver, local_mapper],
        multiprocessing=True,
    )

    odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
    launcher.inputs(location=odom_topic)

    # The simulated robot in the arena built from the same map (instead of Webots), where Webots starts it
    sim = Simulator("sim", config=SimulatorConfig(world=map_server.config.map_file_path, spawn=(0.0, 0.0, 0.0)))
    sim.inputs(command=Topic(name="/cmd_vel", msg_type=cmd_type))
    sim.outputs(odom=odom_topic)
    launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)

    launcher.robot = my_robot
    launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")

    # 6. UI
    launcher.enable_ui(
        inputs=[planner.ui_main_action_input],
        outputs=[
            map_server.get_out_topic(TopicsKeys.GLOBAL_MAP),
            odom_topic,
            planner.get_out_topic(TopicsKeys.GLOBAL_PLAN),
        ],
    )

    launcher.bringup()


if __name__ == "__main__":
    kompass_bringup()
