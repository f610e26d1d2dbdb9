"""The navigation components (Kompass' nodes without ROS): each wires algorithms of
``emos.actors.nav`` to keyed topics and runs as its own process.

    from emos.actors.nav.components import Planner, Controller, DriveManager, TopicsKeys

Porting a Kompass recipe: ``kompass.components`` -> ``emos.actors.nav.components``;
``kompass.robot``, ``kompass.control``, ``kompass_core.models`` -> ``emos.actors.nav``;
``kompass.ros`` (Topic, Launcher) -> ``emos``.
"""
from ..local_map import MapConfig, MapperConfig
from .behaviors import Behaviors, BehaviorsConfig
from .controller import Controller, ControllerConfig
from .docking import DockingServer, DockingServerConfig
from .drive_manager import DriveManager, DriveManagerConfig
from .keys import TopicsKeys
from .local_mapper import LocalMapper, LocalMapperConfig
from .localizer import Localizer, LocalizerConfig
from .map_server import MapServer, MapServerConfig
from .motion_server import MotionServer, MotionServerConfig
from .planner import Planner, PlannerConfig
from .waypoints import WaypointFollower, WaypointFollowerConfig

__all__ = [
    "Behaviors", "BehaviorsConfig", "DockingServer", "DockingServerConfig", "WaypointFollower", "WaypointFollowerConfig",
    "Controller", "ControllerConfig", "DriveManager", "DriveManagerConfig", "LocalMapper", "LocalMapperConfig",
    "Localizer", "LocalizerConfig",
    "MapConfig", "MapperConfig", "MapServer", "MapServerConfig", "MotionServer", "MotionServerConfig", "Planner", "PlannerConfig", "TopicsKeys",
]
