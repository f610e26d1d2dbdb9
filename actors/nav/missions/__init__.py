"""Waypoint missions (Nav2's waypoint follower): the pure mission state machine and the tasks
run at a waypoint. The ``WaypointFollower`` component (components/waypoints.py) wires them."""
from .mission import WaypointMission
from .tasks import ActionAtWaypoint, PhotoAtWaypoint, TaskOutcome, WaitAtWaypoint, WaypointTask

__all__ = ["WaypointMission", "WaypointTask", "WaitAtWaypoint", "ActionAtWaypoint", "PhotoAtWaypoint", "TaskOutcome"]
