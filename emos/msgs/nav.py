"""nav_msgs."""
from __future__ import annotations

import numpy as np

from emos.msgs import fields as F
from emos.msgs.geometry import Pose, PoseStamped, PoseWithCovariance, TwistWithCovariance
from emos.msgs.registry import Message, message_type
from emos.msgs.std import Header, Time


@message_type("nav_msgs")
class Odometry(Message):
    header: Header = F.message(Header)
    child_frame_id: str = F.string()
    pose: PoseWithCovariance = F.message(PoseWithCovariance)
    twist: TwistWithCovariance = F.message(TwistWithCovariance)


@message_type("nav_msgs")
class Path(Message):
    header: Header = F.message(Header)
    poses: list[PoseStamped] = F.message_list(PoseStamped)


@message_type("nav_msgs")
class MapMetaData(Message):
    map_load_time: Time = F.message(Time)
    resolution: float = F.float32()
    width: int = F.integer(bits=32, signed=False)
    height: int = F.integer(bits=32, signed=False)
    origin: Pose = F.message(Pose)


@message_type("nav_msgs")
class OccupancyGrid(Message):
    """Row-major grid, row 0 at the origin (lowest y); -1 unknown, 0..100 occupancy."""

    header: Header = F.message(Header)
    info: MapMetaData = F.message(MapMetaData)
    data: np.ndarray = F.array(dtype="int8", ndim=1)

    def grid(self) -> np.ndarray:
        """A (height, width) view of ``data``."""
        return self.data.reshape(self.info.height, self.info.width)
