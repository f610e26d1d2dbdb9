"""``StartVisionTracking``: sends the controller's ``track_vision_target`` goal once it is up.

The spec starts vision following from the shell (``ros2 action send_goal
/<controller>/track_vision_target ... "{label: 'person'}"``). In a recipe, this small component
does the same from inside the system: when it activates it waits for the controller's action
server, sends one goal with the label, logs the controller's feedback changes and the result.
It sends the goal once: when the target is lost for good (search disabled or timed out) the
action ends and so does the following, as in the spec.
"""
from __future__ import annotations

import threading
import uuid
from typing import Any

from emos.config.base import BaseComponentConfig
from emos.core.component import BaseComponent
from emos.core.rpc import RpcConnectionError

from .interfaces import TrackVisionTargetFeedback, TrackVisionTargetGoal, TrackVisionTargetResult

__all__ = ["StartVisionTracking"]


class StartVisionTracking(BaseComponent):
    """Sends ``TrackVisionTargetGoal(label, search_radius, search_timeout)`` to
    ``<controller_name>/track_vision_target`` after activation (retrying until the server is up,
    at most ``connect_timeout`` seconds)."""

    def __init__(self, *, component_name: str, controller_name: str, label: str, search_radius: float = 0.0,
                 search_timeout: float = 0.0, connect_timeout: float = 60.0) -> None:
        if not isinstance(controller_name, str) or not controller_name:
            raise ValueError(f"component {component_name!r}: controller_name must be the Controller's component name, got {controller_name!r}")
        if not isinstance(label, str) or not label:
            raise ValueError(f"component {component_name!r}: label must be a non-empty detection label (e.g. 'person'), got {label!r}")
        if not connect_timeout > 0:
            raise ValueError(f"component {component_name!r}: connect_timeout must be > 0 s, got {connect_timeout!r}")
        super().__init__(component_name=component_name, config=BaseComponentConfig(loop_rate=1.0))
        self.action_name = f"{controller_name}/track_vision_target"
        self.goal = TrackVisionTargetGoal(label=label, search_radius=float(search_radius), search_timeout=float(search_timeout))
        self.connect_timeout = float(connect_timeout)
        self._stop: threading.Event | None = None  # made at activation (keeps the component copyable)
        self._thread: threading.Thread | None = None
        self.result: TrackVisionTargetResult | None = None

    def custom_on_activate(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"{self.component_name}-goal", daemon=True)
        self._thread.start()

    def custom_on_deactivate(self) -> None:
        if self._stop is not None:
            self._stop.set()
        client, goal_id = getattr(self, "_client", None), getattr(self, "_goal_id", None)
        if client is not None and goal_id is not None and self.result is None:
            try:  # a goal in flight is cancelled: the controller stops the robot
                client.cancel(goal_id)
            except (RpcConnectionError, OSError) as exc:  # the controller is gone already
                self.get_logger().info("[%s] cancelling %s: %s", self.component_name, self.action_name, exc)

    def _execution_step(self, **kwargs: Any) -> None:
        pass

    def _run(self) -> None:
        from emos.core.retry import Backoff, retry
        from emos.core.services import ActionCanceled, ActionClient

        stop = self._stop
        assert stop is not None
        client = ActionClient(self.action_name, TrackVisionTargetGoal, TrackVisionTargetFeedback, TrackVisionTargetResult)
        self._client, self._goal_id, self.result = client, uuid.uuid4().hex, None
        log = self.get_logger()
        log.info("[%s] sending %s goal (label %r)", self.component_name, self.action_name, self.goal.label)

        def send() -> TrackVisionTargetResult:
            if stop.is_set():  # deactivated while waiting: no goal after that
                raise RpcConnectionError(f"{self.component_name} deactivated")
            return client.send_goal(self.goal, feedback_callback=self._feedback, goal_id=self._goal_id)

        try:
            # Until the controller serves the action (it may start after this component), and
            # again (the same goal id) if it died under the goal, within connect_timeout of the
            # first try; a deactivation ends the wait.
            self.result = retry(send,
                                Backoff(base=0.5, factor=1.0, timeout=self.connect_timeout), retry_on=RpcConnectionError,
                                retry_if=lambda _exc: not stop.is_set(), sleep=stop.wait)
        except ActionCanceled:
            log.info("[%s] %s goal cancelled", self.component_name, self.action_name)
            return
        except RpcConnectionError as exc:
            if not stop.is_set():
                message = f"action {self.action_name} not reachable within {self.connect_timeout:.0f} s: {exc}"
                log.error("[%s] %s", self.component_name, message)
                self.health_status.set_fail_system(message=message)
            return
        (log.info if self.result.success else log.warning)(
            "[%s] %s ended: success=%s, %s", self.component_name, self.action_name, self.result.success, self.result.message)

    _last_visible: bool | None = None

    def _feedback(self, feedback: TrackVisionTargetFeedback) -> None:
        if feedback.target_visible != self._last_visible:  # log changes, not every control period
            self._last_visible = feedback.target_visible
            self.get_logger().info("[%s] target %r %s (status %s)", self.component_name, self.goal.label,
                                   "visible" if feedback.target_visible else "not visible", feedback.status)
