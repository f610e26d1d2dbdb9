"""Request, goal, feedback and result types of the navigation services and actions
(the ``kompass_interfaces`` of the ROS original, as EMOS messages)."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.geometry import Pose, PoseStamped
from emos.msgs.nav import Path
from emos.msgs.registry import Message, message_type

_PKG = "kompass_interfaces"


# -- Planner: PlanPath (service and action) ------------------------------------------------------
@message_type(_PKG, name="PlanPath_Request")
class PlanPathRequest(Message):
    """``any_heading``: plan to (x, y) and arrive at whatever heading is shortest."""

    goal: PoseStamped = F.message(PoseStamped)
    any_heading: bool = F.boolean(True)


@message_type(_PKG, name="PlanPath_Response")
class PlanPathResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()
    plan: Path = F.message(Path)


@message_type(_PKG, name="PathTrackingError")
class PathTrackingError(Message):
    """How far from a pose still counts as there: heading (rad) and distance (m)."""

    orientation_error: float = F.float64()
    lateral_distance_error: float = F.float64()


@message_type(_PKG, name="PlanPath_Goal")
class PlanPathGoal(Message):
    """The Planner's action goal (Kompass' ``PlanPath.Goal``): ``goal`` is a position in the
    world frame (``frames.world``); the Planner plans to it at any heading.
    ``end_tolerance.lateral_distance_error`` (m): the robot has arrived within it (0: the
    config's ``distance_tolerance``). ``end_tolerance.orientation_error`` is not checked: the
    arrival heading is whatever the path ends with."""

    goal: Pose = F.message(Pose)
    end_tolerance: PathTrackingError = F.message(PathTrackingError)


@message_type(_PKG, name="PlanPath_Feedback")
class PlanPathFeedback(Message):
    distance_to_goal: float = F.float64()
    plan_length: float = F.float64()


@message_type(_PKG, name="PlanPath_Result")
class PlanPathResult(Message):
    success: bool = F.boolean()
    message: str = F.string()
    plan: Path = F.message(Path)


class PlanPath:
    """The Planner's action as a ROS action type: ``PlanPath.Goal()``, ``PlanPath.Feedback``,
    ``PlanPath.Result`` (what ``ComponentActions.send_action_goal(action_type=PlanPath)`` takes)."""

    Goal, Feedback, Result = PlanPathGoal, PlanPathFeedback, PlanPathResult


# -- Controller: ControlPath and TrackVisionTarget (actions) -------------------------------------
@message_type(_PKG, name="ControlPath_Goal")
class ControlPathGoal(Message):
    """``path``: the path to follow; empty: follow the latest message on the ``plan`` input."""

    path: Path = F.message(Path)


@message_type(_PKG, name="ControlPath_Feedback")
class ControlPathFeedback(Message):
    distance_left: float = F.float64()
    status: str = F.string()


@message_type(_PKG, name="ControlPath_Result")
class ControlPathResult(Message):
    success: bool = F.boolean()
    message: str = F.string()


@message_type(_PKG, name="TrackVisionTarget_Goal")
class TrackVisionTargetGoal(Message):
    """Follow the detection labelled ``label``; ``search_radius`` (m) and ``search_timeout`` (s)
    of 0 keep the follower's configured search behaviour."""

    label: str = F.string()
    search_radius: float = F.float64()
    search_timeout: float = F.float64()


@message_type(_PKG, name="TrackVisionTarget_Feedback")
class TrackVisionTargetFeedback(Message):
    status: str = F.string()
    target_visible: bool = F.boolean()


@message_type(_PKG, name="TrackVisionTarget_Result")
class TrackVisionTargetResult(Message):
    success: bool = F.boolean()
    message: str = F.string()


class TrackVisionTarget:
    """The Controller's ``track_vision_target`` action as a ROS action type (``TrackVisionTarget.Goal()``)."""

    Goal, Feedback, Result = TrackVisionTargetGoal, TrackVisionTargetFeedback, TrackVisionTargetResult


# -- MapServer: Save2dMapToFile (service) ----------------------------------------------------------
@message_type(_PKG, name="Save2dMapToFile_Request")
class SaveMapRequest(Message):
    """``file_location``: folder (default: the config's); ``file_name``: stem of the YAML/PGM pair."""

    file_location: str = F.string()
    file_name: str = F.string()


@message_type(_PKG, name="Save2dMapToFile_Response")
class SaveMapResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()
    path: str = F.string()


# -- MotionServer: MotionRecording (action) --------------------------------------------------------
@message_type(_PKG, name="MotionRecording_Goal")
class MotionRecordingGoal(Message):
    """Record command and odometry every ``timestep`` s for ``duration`` s into a CSV."""

    duration: float = F.float64(10.0)
    timestep: float = F.float64(0.1)
    name: str = F.string()


@message_type(_PKG, name="MotionRecording_Feedback")
class MotionRecordingFeedback(Message):
    samples: int = F.integer()


@message_type(_PKG, name="MotionRecording_Result")
class MotionRecordingResult(Message):
    success: bool = F.boolean()
    message: str = F.string()
    file: str = F.string()


# -- Planner: path files and recording (services) ------------------------------------------------------
@message_type(_PKG, name="PathFromToFile_Request")
class PathFromToFileRequest(Message):
    file_location: str = F.string()
    file_name: str = F.string()


@message_type(_PKG, name="PathFromToFile_Response")
class PathFromToFileResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()


@message_type(_PKG, name="StartPathRecording_Request")
class StartPathRecordingRequest(Message):
    """Record the robot's location every ``recording_time_step`` s until the next save."""

    recording_time_step: float = F.float64(0.1)


@message_type(_PKG, name="StartPathRecording_Response")
class StartPathRecordingResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()


# -- Service types (``kompass_interfaces.srv``): what ``ServiceClientConfig(srv_type=...)``,
# ``send_srv_request(srv_type=...)`` and ``trigger_service`` take ----------------------------------
class PathFromToFile:
    """The Planner's ``save_plan_to_file`` and ``load_plan_from_file`` services:
    ``PathFromToFile.Request(file_location=..., file_name=...)``, ``PathFromToFile.Response``."""

    Request, Response = PathFromToFileRequest, PathFromToFileResponse


class StartPathRecording:
    """The Planner's ``start_path_recording`` service: ``StartPathRecording.Request(recording_time_step=0.1)``."""

    Request, Response = StartPathRecordingRequest, StartPathRecordingResponse


class Save2dMapToFile:
    """The MapServer's ``save_map`` service: ``Save2dMapToFile.Request(file_location=..., file_name=...)``."""

    Request, Response = SaveMapRequest, SaveMapResponse
