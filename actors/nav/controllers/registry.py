"""Controller lookup by id: ``make_controller("DWA", robot)`` (what the Controller component uses)."""
from __future__ import annotations

from typing import Any

from ..robot import RobotConfig
from .arc_sampler import ArcSampler, ArcSamplerConfig
from .base import ControllersID
from .dvz import DVZ, DVZConfig
from .dwa import DWA, DWAConfig
from .mppi import MPPI, MPPIConfig
from .pure_pursuit import PurePursuit, PurePursuitConfig
from .rpp import RegulatedPurePursuit, RegulatedPurePursuitConfig
from .stanley import Stanley, StanleyConfig
from .vision_rgb import VisionRGBFollower, VisionRGBFollowerConfig
from .vision_rgbd import VisionRGBDFollower, VisionRGBDFollowerConfig

__all__ = ["CONTROLLERS", "make_controller"]

#: id -> (controller class, its config class)
CONTROLLERS: dict[ControllersID, tuple[type, type]] = {
    ControllersID.STANLEY: (Stanley, StanleyConfig),
    ControllersID.DWA: (DWA, DWAConfig),
    ControllersID.DVZ: (DVZ, DVZConfig),
    ControllersID.PURE_PURSUIT: (PurePursuit, PurePursuitConfig),
    ControllersID.VISION_IMG: (VisionRGBFollower, VisionRGBFollowerConfig),
    ControllersID.VISION_DEPTH: (VisionRGBDFollower, VisionRGBDFollowerConfig),
    ControllersID.ARC_SAMPLER: (ArcSampler, ArcSamplerConfig),
    ControllersID.MPPI: (MPPI, MPPIConfig),
    ControllersID.REGULATED_PURE_PURSUIT: (RegulatedPurePursuit, RegulatedPurePursuitConfig),
}


def make_controller(algorithm: ControllersID | str, robot: RobotConfig, config: Any = None, **kwargs: Any) -> Any:
    """Build the controller ``algorithm`` for ``robot``.

    ``config`` must be that controller's config class (or None for the defaults); extra
    keyword arguments go to the constructor (``intrinsics=`` for the RGB-D follower).
    """
    cid = ControllersID.from_any(algorithm)
    cls, config_cls = CONTROLLERS[cid]
    if config is not None and not isinstance(config, config_cls):
        raise TypeError(f"config for {cid.value}: expected {config_cls.__name__}, got {type(config).__name__}")
    if cid is ControllersID.VISION_DEPTH:
        if "intrinsics" not in kwargs:
            raise TypeError("VisionRGBDFollower needs intrinsics=CameraIntrinsics(fx, fy, cx, cy)")
        return cls(robot, kwargs.pop("intrinsics"), config, **kwargs)
    return cls(robot, config, **kwargs)
