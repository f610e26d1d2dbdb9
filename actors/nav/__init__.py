"""Navigation algorithm core (Kompass without ROS): numpy in, commands and paths out.

This package imports only numpy and attrs. The planning side (maps, FCL collision, OMPL
planners, paths) lives in its own modules (``emos.actors.nav.maps``, ``.collision``,
``.planning``, ``.paths``) and is imported from there, so that ``import emos.actors.nav``
never pays for OMPL or FCL.
"""
from .controllers import (
    DVZ,
    DWA,
    BoundingBox,
    CameraIntrinsics,
    ControllersID,
    ControlResult,
    ControlStatus,
    DVZConfig,
    DWAConfig,
    LaserScan2D,
    OccupancyGrid2D,
    PurePursuit,
    PurePursuitConfig,
    Stanley,
    StanleyConfig,
    VisionRGBDFollower,
    VisionRGBDFollowerConfig,
    VisionRGBFollower,
    VisionRGBFollowerConfig,
    make_controller,
)
from .costs import TrajectoryCostsWeights, evaluate_costs
from .local_map import LocalMapper, MapConfig, MapperConfig
from .robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig, RobotFrames, RobotGeometry, RobotType
from .safety import CommandFilter, CommandFilterConfig, DriveSafety, SafetyZones, SafetyZonesConfig

__all__ = [
    "AngularCtrlLimits",
    "BoundingBox",
    "CameraIntrinsics",
    "CommandFilter",
    "CommandFilterConfig",
    "ControlResult",
    "ControlStatus",
    "ControllersID",
    "DVZ",
    "DriveSafety",
    "DVZConfig",
    "DWA",
    "DWAConfig",
    "LaserScan2D",
    "LinearCtrlLimits",
    "LocalMapper",
    "MapConfig",
    "MapperConfig",
    "OccupancyGrid2D",
    "PurePursuit",
    "PurePursuitConfig",
    "RobotConfig",
    "RobotFrames",
    "RobotGeometry",
    "RobotType",
    "SafetyZones",
    "SafetyZonesConfig",
    "Stanley",
    "StanleyConfig",
    "TrajectoryCostsWeights",
    "VisionRGBDFollower",
    "VisionRGBDFollowerConfig",
    "VisionRGBFollower",
    "VisionRGBFollowerConfig",
    "evaluate_costs",
    "make_controller",
]
