"""The usage examples of the spec's navigation chapters, imports changed, build as written."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.unit


def test_planner_controller_driver_mapper_server_usage_examples(tmp_path):
    from emos import Topic
    from emos.actors.nav import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotGeometry, RobotType
    from emos.actors.nav.components import (
        Controller,
        ControllerConfig,
        DriveManager,
        DriveManagerConfig,
        LocalMapper,
        LocalMapperConfig,
        MapperConfig,
        MapServer,
        MapServerConfig,
        MotionServer,
        MotionServerConfig,
        Planner,
        PlannerConfig,
        TopicsKeys,
    )
    from emos.config import ComponentRunType

    my_robot = RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.1, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=1.5, max_decel=2.5),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.0, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
    )
    planner = Planner(component_name="planner", config=PlannerConfig(robot=my_robot, loop_rate=1.0))
    planner.run_type = ComponentRunType.EVENT
    planner.inputs(goal_point=Topic(name="/clicked_point", msg_type="PoseStamped"))
    assert planner.ui_main_action_input.name == "/clicked_point"
    assert planner.get_out_topic(TopicsKeys.GLOBAL_PLAN).name == "/plan"

    my_controller = Controller(component_name="controller", config=ControllerConfig(loop_rate=10.0))
    my_controller.inputs(plan=Topic(name="/global_path", msg_type="Path"))
    my_controller.run_type = "ActionServer"
    my_controller.plugin = "DWA"
    assert my_controller.algorithm.value == "DWA"

    driver = DriveManager(component_name="driver", config=DriveManagerConfig(
        closed_loop=True, critical_zone_distance=0.1, slowdown_zone_distance=0.3, critical_zone_angle=90.0))
    driver.outputs(robot_command=Topic(name="/my_robot_cmd", msg_type="Twist"))
    assert driver.get_out_topic(TopicsKeys.FINAL_COMMAND).name == "/my_robot_cmd"

    mapper = LocalMapper(component_name="mapper", config=LocalMapperConfig(loop_rate=10.0, map_params=MapperConfig(width=5.0, height=5.0, resolution=0.2)))
    assert mapper.get_out_topic(TopicsKeys.LOCAL_MAP).name == "/local_map/occupancy_layer"

    server = MapServer(component_name="map_server", config=MapServerConfig(
        map_file_path=str(tmp_path / "environment.pcd"), map_file_read_rate=5.0, grid_resolution=0.1, pc_publish_row=False))
    assert server.get_out_topic(TopicsKeys.GLOBAL_MAP).qos_profile.durability.value == "TRANSIENT_LOCAL"

    motion_server = MotionServer(component_name="motion_server", config=MotionServerConfig(step_test_velocity=1.0, step_test_duration=5.0))
    motion_server.run_type = "Event"
    motion_server.inputs(run_tests=Topic(name="/start_calibration", msg_type="Bool"))
    assert motion_server.get_in_topic(TopicsKeys.RUN_TESTS).name == "/start_calibration"


def test_bad_configs_fail_at_definition_naming_the_field():
    from emos.actors.nav.components import Controller, DriveManagerConfig, PlannerConfig

    with pytest.raises(ValueError, match="slowdown_zone_distance"):
        DriveManagerConfig(critical_zone_distance=0.5, slowdown_zone_distance=0.3)
    with pytest.raises(ValueError, match="unknown planner 'Dijkstra2'"):
        PlannerConfig(planner_id="Dijkstra2")
    c = Controller(component_name="c")
    with pytest.raises(ValueError, match="controller id"):
        c.algorithm = "MPC"
    with pytest.raises(TypeError, match="algorithms_config"):
        c.algorithms_config = {"lookahead": 1.0}
    with pytest.raises(TypeError, match="direct_sensor"):
        c.direct_sensor = "yes"


def test_fallback_actions_of_the_spec_exist():
    from emos.actors.nav.components import Controller, DriveManager
    from emos.actors.nav.controllers import ControllersID

    controller = Controller(component_name="controller")
    controller.algorithm = ControllersID.DWA
    assert controller.set_algorithm(ControllersID.PURE_PURSUIT) and controller.algorithm is ControllersID.PURE_PURSUIT
    assert controller.update_parameter("use_direct_sensor", True) and controller.direct_sensor
    assert controller.update_parameter("algorithm", "VisionRGBDFollower") and controller.algorithm is ControllersID.VISION_DEPTH
    driver = DriveManager(component_name="drive_manager")
    for name in ("stop", "move_to_unblock", "move_forward", "move_backward", "rotate_in_place"):
        assert callable(getattr(driver, name))
