"""The mission parts of ``emos.actors.nav.stacks``: the patrol and docking recipes build their
stack, recovery behaviors, docking server and waypoint follower through it, wired to its topics,
with the recovery behaviors and the docking server on DriveManager inputs above the Controller."""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.stacks import (
    BEHAVIORS_COMMAND,
    COMMAND_INPUTS,
    CONTROLLER_COMMAND,
    DOCKING_COMMAND,
    MOVERS_HOLD,
    point_navigation_stack,
)

pytestmark = pytest.mark.unit

ROBOT = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER, geometry_params=np.array([0.2, 0.3]))
ODOM = Topic(name="/odom", msg_type="Odometry")
SCAN = Topic(name="/sim/scan", msg_type="LaserScan")


def _stack(**kwargs):
    return point_navigation_stack(ROBOT, RobotFrames(world="map", odom="map"), "house.yaml", odom=ODOM,
                                  command=Topic(name="/cmd_vel", msg_type="Twist"), scan=SCAN, **kwargs)


def test_mission_parts_are_wired_to_the_stack_and_ranked_above_the_controller():
    stack = _stack(command_inputs=COMMAND_INPUTS)
    ranks = {c.topic: c.priority for c in stack.driver.config.command_inputs}
    assert ranks[DOCKING_COMMAND.name] > ranks[BEHAVIORS_COMMAND.name] > ranks[CONTROLLER_COMMAND.name]
    assert stack.controller.get_out_topic("command").name == CONTROLLER_COMMAND.name
    behaviors, docking, follower = stack.behaviors(), stack.docking_server(), stack.waypoint_follower()
    assert behaviors.get_out_topic("robot_command").name == BEHAVIORS_COMMAND.name
    assert docking.get_out_topic("robot_command").name == DOCKING_COMMAND.name
    for part in (behaviors, docking):
        assert part.get_in_topic("sensor_data").name == SCAN.name and part.get_in_topic("location").name == ODOM.name
    assert behaviors.get_in_topic("local_map") == stack.local_mapper.get_out_topic("local_map")
    assert behaviors.config.local_mapper == stack.local_mapper.component_name
    assert follower.get_out_topic("goal_point") == stack.planner.get_in_topic("goal_point")
    assert follower.get_in_topic("reached_end") == stack.planner.get_out_topic("reached_end")


def test_a_mission_part_on_a_stack_without_its_command_input_is_refused():
    stack = _stack()  # the Controller's one input: today's stacks
    with pytest.raises(ValueError, match=r"Behaviors 'behaviors' drives through the DriveManager's command input /control/behaviors"):
        stack.behaviors()
    with pytest.raises(ValueError, match=r"command_inputs=COMMAND_INPUTS"):
        stack.docking_server()


def test_movers_gives_the_controller_the_moving_obstacle_tracker():
    from emos.actors.nav.controllers import ArcSamplerConfig, ControllersID

    stack = _stack(movers=True)
    assert stack.controller.config.algorithm == ControllersID.ARC_SAMPLER.value
    config = stack.controller.algorithms_config
    assert isinstance(config, ArcSamplerConfig) and config.movers is not None
    assert config.movers.prediction.hold == MOVERS_HOLD  # never stop where a mover arrives within that long
    assert stack.controller.get_in_topic("sensor_data").name == SCAN.name  # movers are tracked in the scan
    assert stack.planner.config.planner_id == "CostToGo"  # the ArcSampler's pairing: paths in the middle of doorways


def test_people_layer_plans_on_costtogo_and_takes_the_behaviors_band():
    from emos.actors.nav.components.behaviors import BehaviorsConfig
    from emos.actors.nav.stacks import PEOPLE_BAND

    plain = _stack(command_inputs=COMMAND_INPUTS)
    assert not plain.planner.config.people.enabled and plain.planner.get_in_topic("people") is None
    assert plain.behaviors().get_out_topic("people") is None
    stack = _stack(command_inputs=COMMAND_INPUTS, people_layer=True)
    assert stack.planner.config.planner_id == "CostToGo" and stack.planner.config.people.enabled
    behaviors = stack.behaviors(config=BehaviorsConfig(passage_guard={"enabled": True}))
    assert behaviors.get_out_topic("people").name == stack.planner.get_in_topic("people").name == PEOPLE_BAND.name
    with pytest.raises(ValueError, match="passage_guard"):  # the band is the passage guard's
        _stack(command_inputs=COMMAND_INPUTS, people_layer=True).behaviors()


def test_the_behaviors_and_drive_manager_get_the_stacks_map_for_movers_on_walls_when_the_pose_is_in_its_frame():
    import os

    import emos.actors.sim.data as data
    from emos.actors.nav.components.behaviors import BehaviorsConfig

    house = os.path.join(os.path.dirname(data.__file__), "house.yaml")

    def stack(odom_frame: str):
        return point_navigation_stack(ROBOT, RobotFrames(world="map", odom=odom_frame), house, odom=ODOM,
                                      command=Topic(name="/cmd_vel", msg_type="Twist"), scan=SCAN, command_inputs=COMMAND_INPUTS)

    assert stack("map").behaviors().config.static_map == house
    assert stack("odom").behaviors().config.static_map == ""  # raw odometry drifts off the map's frame
    assert stack("map").driver.config.static_map == house  # the DriveManager's mover trails too
    assert stack("odom").driver.config.static_map == ""
    mine = BehaviorsConfig(static_map=house, static_map_clearance=0.0)  # the user's choice stands (0: off)
    assert stack("map").behaviors(config=mine).config is mine
    assert _stack(command_inputs=COMMAND_INPUTS).behaviors().config.static_map == ""  # no such file here
