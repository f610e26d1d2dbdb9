"""Local controllers: path followers (Pure Pursuit, Stanley, DWA, DVZ) and vision followers."""
from .arc_sampler import ArcSampler, ArcSamplerConfig
from .base import ControllersID, ControlResult, ControlStatus
from .dvz import DVZ, DVZConfig
from .dwa import DWA, DWAConfig
from .mppi import MPPI, MPPIConfig
from .pure_pursuit import PurePursuit, PurePursuitConfig
from .registry import CONTROLLERS, make_controller
from .rpp import RegulatedPurePursuit, RegulatedPurePursuitConfig
from .sensors import LaserScan2D, OccupancyGrid2D, obstacle_points
from .stanley import Stanley, StanleyConfig
from .vision_common import BoundingBox, CameraIntrinsics
from .vision_rgb import VisionRGBFollower, VisionRGBFollowerConfig
from .vision_rgbd import VisionRGBDFollower, VisionRGBDFollowerConfig

__all__ = [
    "ArcSampler",
    "ArcSamplerConfig",
    "CONTROLLERS",
    "make_controller",
    "ControllersID",
    "ControlResult",
    "ControlStatus",
    "LaserScan2D",
    "OccupancyGrid2D",
    "PurePursuit",
    "PurePursuitConfig",
    "DVZ",
    "DVZConfig",
    "DWA",
    "DWAConfig",
    "MPPI",
    "MPPIConfig",
    "RegulatedPurePursuit",
    "RegulatedPurePursuitConfig",
    "Stanley",
    "StanleyConfig",
    "BoundingBox",
    "CameraIntrinsics",
    "VisionRGBFollower",
    "VisionRGBFollowerConfig",
    "VisionRGBDFollower",
    "VisionRGBDFollowerConfig",
    "obstacle_points",
]
