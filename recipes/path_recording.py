"""Path recording and replay: the Planner's save / load / record services on the simulated house.

    emos run recipes/path_recording.py

The Planner offers three services (request types in ``emos.actors.nav.components.interfaces``):

* ``planner/save_plan_to_file`` (PathFromToFile: ``file_location``, ``file_name``): the current
  plan, or the recorded path while recording (saving stops the recording), as CSV ``x,y,yaw``;
* ``planner/load_plan_from_file`` (PathFromToFile): publishes the file as the global plan, and
  the Controller follows it;
* ``planner/start_path_recording`` (StartPathRecording: ``recording_time_step``): records the
  robot's location.

From Python (another process)::

    from emos.core.services import ServiceClient
    from emos.actors.nav.components.interfaces import PathFromToFileRequest, PathFromToFileResponse
    save = ServiceClient("planner/save_plan_to_file", PathFromToFileRequest, PathFromToFileResponse)
    save.call(PathFromToFileRequest(file_location="/tmp", file_name="computed_path.csv"))

Goals: ``emos topic pub /goal PointStamped '{"point": {"x": 7.0, "y": 2.5}}'``, or from the web
UI, which shows the map, the plan and the robot (open the link the run prints; docs/ui.md). The
spec also lists the three services as UI inputs; EMOS's UI sends topics and actions, so the
services are called as above.
"""
import numpy as np

from emos import Launcher, Topic
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
from emos.actors.nav.controllers import ControllersID
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.data import HOUSE_MAP

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

driver = DriveManager(component_name="drive_manager", config=DriveManagerConfig(critical_zone_distance=0.05))
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))

map_server = MapServer(
    component_name="global_map_server",
    config=MapServerConfig(map_file_path=str(HOUSE_MAP), grid_resolution=0.5),
)

sim = Simulator("sim", config=SimulatorConfig(world="house", spawn=(1.5, 1.5, 0.0)))
odom_topic = Topic(name="/odometry/filtered", msg_type="Odometry")
sim.inputs(command=Topic(name="/cmd_vel", msg_type="Twist"))
sim.outputs(odom=odom_topic)

# 3. Launch
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.kompass(components=[map_server, planner, driver, controller], multiprocessing=True)
launcher.inputs(location=odom_topic)
launcher.robot = my_robot
launcher.frames = RobotFrames(world="map", odom="map", scan="LDS-01")
# 4. Enable the web UI: goals from the page; the map, the robot and its plan on it
launcher.enable_ui(
    inputs=[planner.ui_main_action_input],
    outputs=[
        map_server.get_out_topic(TopicsKeys.GLOBAL_MAP),
        odom_topic,
        planner.get_out_topic(TopicsKeys.GLOBAL_PLAN),
    ],
)
launcher.bringup()
