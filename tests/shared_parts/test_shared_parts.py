"""The parts the recipes, the CLI and Cortex share, without processes: the point-navigation
stack (emos.actors.nav.stacks) and the reading of a run's tree and ``info`` answers
(emos.core.discovery)."""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos.actors.nav import RobotConfig, RobotFrames, RobotGeometry, RobotType
from emos.actors.nav.components.map_pose import MapFramePose
from emos.actors.nav.stacks import point_navigation_stack
from emos.core.discovery import component_workers, interfaces_of, supervisor_nodes, worker_nodes
from emos.core.services import describe_interfaces

pytestmark = pytest.mark.unit

ROBOT = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.1, 0.3]))
ODOM = Topic(name="/odom", msg_type="Odometry")
CMD = Topic(name="/cmd_vel", msg_type="Twist")


class _Launcher:
    """What the stack asks of a Launcher, recorded."""

    def __init__(self) -> None:
        self.packages: list[tuple[str, list[str]]] = []
        self.robot = self.frames = None

    def kompass(self, components: list, multiprocessing: bool) -> None:
        self.packages.append(("kompass", [c.component_name for c in components]))

    def add_pkg(self, components: list, package_name: str, multiprocessing: bool) -> None:
        self.packages.append((package_name, [c.component_name for c in components]))


def test_unlocalized_stack_reads_the_odometry_as_location():
    scan = Topic(name="/scan_front", msg_type="LaserScan")
    frames = RobotFrames(world="map", odom="map", scan="laser")
    stack = point_navigation_stack(ROBOT, frames, "/nonexistent/map.yaml", odom=ODOM, command=CMD, scan=scan)
    launcher = _Launcher()
    stack.launch(launcher)
    assert launcher.packages == [("kompass", ["global_map_server", "controller", "planner", "drive_manager", "mapper"])]
    assert (launcher.robot, launcher.frames) == (ROBOT, frames)
    assert stack.location is ODOM and stack.localizer is None and stack.map_pose is None
    assert stack.component_names == ["global_map_server", "planner", "controller", "drive_manager", "mapper"]
    for component in (stack.controller, stack.planner, stack.driver, stack.local_mapper):
        assert component.get_in_topic("location").name == "/odom"
    for component in (stack.controller, stack.driver, stack.local_mapper):
        assert component.get_in_topic("sensor_data").name == "/scan_front"
    assert stack.driver.get_out_topic("robot_command").name == "/cmd_vel"


def test_localized_stack_adds_the_localizer_and_the_map_frame_pose():
    frames = RobotFrames(world="map", odom="odom")
    stack = point_navigation_stack(ROBOT, frames, "/nonexistent/map.yaml", odom=ODOM, command=CMD, localize=True,
                                   initial_pose=(1.0, 2.0, 0.5), seed=7)
    launcher = _Launcher()
    stack.launch(launcher)
    assert launcher.packages[1] == ("localization", ["localizer", "map_pose"])
    assert stack.location.name == "/odometry/localized"
    assert isinstance(stack.map_pose, MapFramePose) and stack.map_pose.map_frames == frames
    assert stack.localizer is not None and stack.localizer.config.initial_pose == (1.0, 2.0, 0.5)
    assert stack.localizer.get_in_topic("location").name == "/odom"  # the raw odometry it corrects
    assert stack.controller.get_in_topic("location").name == "/odometry/localized"
    with pytest.raises(ValueError, match="frames.odom"):
        point_navigation_stack(ROBOT, RobotFrames(world="map", odom="map"), "m.yaml", odom=ODOM, command=CMD, localize=True)


def test_workers_of_a_supervisor_tree_skip_what_is_malformed():
    tree = {"kind": "supervisor", "name": "root", "children": [
        {"kind": "worker", "name": "sim"},
        {"kind": "supervisor", "name": "kompass", "children": [{"kind": "worker", "name": "planner"}, "junk",
                                                                {"kind": "worker", "name": 3}, {"kind": "worker"}]},
        {"kind": "supervisor", "name": "x", "children": "not a list"}]}
    assert component_workers(tree) == ["sim", "planner"]
    assert component_workers(None) == [] and component_workers(["a"]) == []
    # The chaos tool walks the same tree for the nodes themselves (pids, modes, groups).
    assert [w.get("name") for w in worker_nodes(tree)] == ["sim", "planner", 3, None]
    assert [g["name"] for g in supervisor_nodes(tree)] == ["root", "kompass", "x"]
    assert worker_nodes("junk") == [] and supervisor_nodes(None) == []


def test_interfaces_of_an_info_answer_keep_whole_entries_with_printable_names():
    from emos.msgs import SetBoolRequest, SetBoolResponse

    described = describe_interfaces([("service", "c/set", (SetBoolRequest, SetBoolResponse)),
                                     ("service", "c/odd", ("NoSuchType", SetBoolResponse))], serving={"c/set"})
    entries = described["services"] + [{"name": "/c/\x1bevil", "request": {"type": "String"}, "response": {"type": "String"}},
                                       {"name": "c/half", "request": {"type": "String"}}, None]
    found = interfaces_of("c", "service", entries)
    assert [(i.name, i.serving) for i in found] == [("c/set", True), ("c/odd", False), ("c/evil", False)]
    assert found[0].registered_types() == (SetBoolRequest, SetBoolResponse)
    assert found[1].registered_types() is None  # a type this process does not know is never imported
    assert interfaces_of("c", "action", "not a list") == []
