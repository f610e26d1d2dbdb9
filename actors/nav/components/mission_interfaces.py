"""Goal, feedback and result types of the behavior, docking and waypoint action servers, with
Nav2's names (``nav2_msgs/action/Spin``, ``BackUp``, ``DockRobot``, ``FollowWaypoints``, ...)."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.geometry import Pose
from emos.msgs.registry import Message, message_type

_PKG = "nav2_msgs"


# -- behaviors (Nav2's behavior server) ------------------------------------------------------------
@message_type(_PKG, name="Spin_Goal")
class SpinGoal(Message):
    target_yaw: float = F.float64(1.5708)  # rad, sign = direction
    time_allowance: float = F.float64(30.0)  # s of the node's clock


@message_type(_PKG, name="BackUp_Goal")
class BackUpGoal(Message):
    distance: float = F.float64(0.3)  # m (Nav2 gives a target Point; its x is the distance)
    speed: float = F.float64(0.1)
    time_allowance: float = F.float64(30.0)


@message_type(_PKG, name="DriveOnHeading_Goal")
class DriveOnHeadingGoal(Message):
    distance: float = F.float64(0.3)
    speed: float = F.float64(0.1)
    time_allowance: float = F.float64(30.0)


@message_type(_PKG, name="Wait_Goal")
class WaitGoal(Message):
    time: float = F.float64(1.0)


@message_type(_PKG, name="Behavior_Feedback")
class BehaviorFeedback(Message):
    behavior: str = F.string()
    progress: float = F.float64()  # 0..1 of the motion done


@message_type(_PKG, name="Behavior_Result")
class BehaviorResult(Message):
    success: bool = F.boolean()
    message: str = F.string()  # why it refused or stopped
    total_elapsed_time: float = F.float64()


# -- docking (Nav2's docking server) ------------------------------------------------------------------
@message_type(_PKG, name="DockRobot_Goal")
class DockRobotGoal(Message):
    dock_id: str = F.string()  # a dock of the server's database; "" = the first one
    max_staging_time: float = F.float64(60.0)


@message_type(_PKG, name="DockRobot_Feedback")
class DockRobotFeedback(Message):
    state: str = F.string()  # NAV_TO_STAGING_POSE, INITIAL_PERCEPTION, CONTROLLING, WAIT_FOR_CHARGE
    distance_left: float = F.float64()


@message_type(_PKG, name="DockRobot_Result")
class DockRobotResult(Message):
    success: bool = F.boolean()
    message: str = F.string()
    error_m: float = F.float64()  # distance from the docked pose of the last detection
    error_deg: float = F.float64()


@message_type(_PKG, name="UndockRobot_Goal")
class UndockRobotGoal(Message):
    dock_id: str = F.string()


# -- waypoints (Nav2's waypoint follower) -------------------------------------------------------------
@message_type(_PKG, name="FollowWaypoints_Goal")
class FollowWaypointsGoal(Message):
    """``poses`` in the world frame; ``number_of_loops``: 0 = once, N = N more times, -1 = until
    cancelled (Nav2's); ``goal_index``: the waypoint to start from (resume)."""

    poses: list[Pose] = F.message_list(Pose)
    number_of_loops: int = F.integer(0)
    goal_index: int = F.integer(0)


@message_type(_PKG, name="FollowWaypoints_Feedback")
class FollowWaypointsFeedback(Message):
    current_waypoint: int = F.integer()
    current_loop: int = F.integer()
    distance_remaining: float = F.float64()
    state: str = F.string()  # navigating, task, failed


@message_type(_PKG, name="FollowWaypoints_Result")
class FollowWaypointsResult(Message):
    success: bool = F.boolean()
    message: str = F.string()
    missed_waypoints: list[str] = F.string_list()  # "<index>: <why>" per waypoint that failed
    next_waypoint: int = F.integer()  # where a resumed goal starts (goal_index)
    loops_done: int = F.integer()
