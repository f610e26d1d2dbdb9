"""The common part of the components that drive the robot through action servers: the
``Behaviors`` (Nav2's behavior server) and the ``DockingServer``.

Both read a scan and a pose, publish velocity commands on ``robot_command`` (wired to one of the
DriveManager's prioritised command inputs in the shipped stacks: ``stacks.BEHAVIORS_COMMAND``,
``stacks.DOCKING_COMMAND``), offer their moves as action servers named ``<component>/<action>``,
stop the robot when a move ends, and answer an action goal by following the move until it has a
result, publishing feedback and passing a cancel on. That is here, once.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic

from .base import NavComponent
from .convert import BadInput, pose_of, twist_msg

__all__ = ["MotionActionServer"]

R = TypeVar("R")

FEEDBACK_PERIOD = 0.1  # wall s between an action's feedback messages (and cancel checks)


class MotionActionServer(NavComponent):
    """A component whose moves are action servers. ``ACTIONS``: (action name, goal, feedback,
    result types, the name of the method that serves a goal handle)."""

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "sensor_data": AllowedTopic(types=("LaserScan",), default=Topic(name="/scan", msg_type="LaserScan"), required=True),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry"), required=True),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "robot_command": AllowedTopic(types=("Twist",), default=Topic(name="/cmd_vel", msg_type="Twist"), required=True),
    }
    ACTIONS: ClassVar[tuple[tuple[str, type, type, type, str], ...]] = ()

    def action_servers(self) -> dict[str, tuple[Any, Any, Any]]:
        return {f"{self.component_name}/{name}": (goal, feedback, result) for name, goal, feedback, result, _ in self.ACTIONS}

    def _create_action_servers(self) -> None:
        """Start every server of ``ACTIONS`` (call from ``custom_on_configure``)."""
        for name, goal, feedback, result, serve in self.ACTIONS:
            self.create_action_server(f"{self.component_name}/{name}", goal, feedback, result, getattr(self, serve))

    def _pose(self) -> np.ndarray | None:
        """(x, y, yaw) from the latest ``location``; None when none arrived or it is malformed."""
        msg = self.latest("location")
        try:
            return None if msg is None else pose_of(msg)
        except BadInput:
            return None

    def _drive(self, command: np.ndarray) -> None:
        self.publish(self.required_out_topic("robot_command"), twist_msg(command))

    def _stop_robot(self) -> None:
        self._drive(np.zeros(3))

    def _follow_goal(self, handle: Any, result: Callable[[], R | None], feedback: Callable[[], Any], cancel: Callable[[], None]) -> R:
        """Serve an action goal whose move runs in the component's loop: until ``result()`` has
        one, publish ``feedback()`` and pass a cancel request on (``cancel()``); return the result."""
        while (answer := result()) is None:
            if handle.is_cancel_requested:
                cancel()
            handle.publish_feedback(feedback())
            time.sleep(FEEDBACK_PERIOD)
        return answer
