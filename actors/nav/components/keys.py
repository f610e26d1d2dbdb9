"""``TopicsKeys``: the input and output keys of the navigation components, as one str enum.

``GLOBAL_MAP`` is the planner's ``map`` input and, through an alias, the map server's
``global_map`` output, so ``map_server.get_out_topic(TopicsKeys.GLOBAL_MAP)`` works as in the spec.
"""
from __future__ import annotations

import enum

__all__ = ["TopicsKeys"]


class TopicsKeys(str, enum.Enum):
    GOAL_POINT = "goal_point"
    GLOBAL_PLAN = "plan"
    GLOBAL_MAP = "map"
    ROBOT_LOCATION = "location"
    SPATIAL_SENSOR = "sensor_data"
    LOCAL_MAP = "local_map"
    VISION_TRACKINGS = "vision_tracking"
    VISION_DETECTIONS = "vision_detections"
    DEPTH_CAM_INFO = "depth_camera_info"
    DEPTH_IMAGE = "depth_image"
    INTERMEDIATE_CMD = "command"
    INTERMEDIATE_CMD_LIST = "multi_command"
    LOCAL_PLAN = "local_plan"
    INTERPOLATED_PATH = "interpolation"
    TRACKED_POINT = "tracked_point"
    FINAL_COMMAND = "robot_command"
    EMERGENCY = "emergency_stop"
    REACHED_END = "reached_end"
    RUN_TESTS = "run_tests"
    SPATIAL_SENSOR_OUT = "spatial_sensor"

    def __str__(self) -> str:
        return self.value
