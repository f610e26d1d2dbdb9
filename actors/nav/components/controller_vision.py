"""Vision target following for the :class:`Controller`: the ``track_vision_target`` action.

Created when the controller has a ``vision_tracking`` (or ``vision_detections``) input. A goal
names a label; every control period the box of the best detection with that label goes to the
VisionRGBFollower (image size from the detection's image or the camera info) or, for
``VisionRGBDFollower``, with the depth image (``depth_image`` input or the detection's own
depth image) and the intrinsics of ``depth_camera_info``. The action ends when the target is
lost for good (search timed out or disabled) or the goal is cancelled.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from emos.geometry import PoseHistory

from ..controllers import BoundingBox, CameraIntrinsics, ControllersID, ControlStatus
from ..controllers.registry import CONTROLLERS, make_controller
from .convert import BadInput, pose_stamped
from .interfaces import TrackVisionTargetFeedback, TrackVisionTargetGoal, TrackVisionTargetResult

__all__ = ["VisionTracking"]

_DEPTH_ENCODINGS = ("16UC1", "32FC1", "mono16")


class VisionTracking:
    """Mixin of the Controller (uses its inputs, config and publishing helpers)."""

    def _vision_input_key(self) -> str | None:
        return next((k for k in ("vision_tracking", "vision_detections") if self.get_in_topic(k) is not None), None)  # type: ignore[attr-defined]

    def vision_action_servers(self) -> dict[str, tuple]:
        """``<name>/track_vision_target`` when the controller has a vision input (it serves it then)."""
        if self._vision_input_key() is None:
            return {}
        return {f"{self.component_name}/track_vision_target": (TrackVisionTargetGoal, TrackVisionTargetFeedback, TrackVisionTargetResult)}  # type: ignore[attr-defined]

    def configure_vision(self) -> None:
        self._tracking = False
        self._vision_key = self._vision_input_key()
        for name, types in self.vision_action_servers().items():
            self.create_action_server(name, *types, self._track_target)  # type: ignore[attr-defined]

    @property
    def tracking_active(self) -> bool:
        return getattr(self, "_tracking", False)

    def _target_box(self, label: str) -> tuple[BoundingBox | None, Any]:
        msg = self.latest(self._vision_key)  # type: ignore[attr-defined]
        if msg is None or self.age_of(self._vision_key) > self.config.sensor_timeout:  # type: ignore[attr-defined]
            return None, msg
        labels = list(msg.labels)
        idx = [i for i, lab in enumerate(labels) if lab == label]
        if not idx:
            return None, msg
        scores = getattr(msg, "scores", None)
        best = max(idx, key=lambda i: float(scores[i])) if scores is not None and len(scores) == len(labels) else idx[0]
        x1, y1, x2, y2 = (float(v) for v in msg.boxes[best])
        width, height = self._image_size(msg)
        if x2 <= x1 or y2 <= y1:
            return None, msg
        return BoundingBox(x1, y1, x2 - x1, y2 - y1, width, height), msg

    def _image_size(self, msg: Any) -> tuple[int, int]:
        image = getattr(msg, "image", None)
        if image is not None and image.width and image.height:
            return int(image.width), int(image.height)
        info = self.latest("depth_camera_info")  # type: ignore[attr-defined]
        if info is not None and info.width and info.height:
            return int(info.width), int(info.height)
        raise BadInput(f"{self.topic_name(self._vision_key)}: detections carry no image and no depth_camera_info is given: the image size is unknown")  # type: ignore[attr-defined]

    def _depth(self, msg: Any, conversion_factor: float) -> np.ndarray | None:
        """The depth image in the units the follower's ``depth_conversion_factor`` turns into
        metres. Integer depth (16UC1, mono16) is the camera's raw units (usually mm), taken as it
        is; 32FC1 is already metres (REP 118), so it is divided by the factor to come out right."""
        image = self.latest("depth_image")  # type: ignore[attr-defined]
        if image is None and msg is not None and getattr(msg, "image", None) is not None and msg.image.encoding in _DEPTH_ENCODINGS:
            image = msg.image
        if image is None:
            return None
        depth = image.to_numpy()
        return depth / conversion_factor if image.encoding == "32FC1" else depth

    def _vision_follower(self) -> Any:
        cid = self.algorithm  # type: ignore[attr-defined]
        if cid not in (ControllersID.VISION_IMG, ControllersID.VISION_DEPTH):
            cid = ControllersID.VISION_IMG
        cfg = self._algorithms_config if isinstance(self._algorithms_config, CONTROLLERS[cid][1]) else CONTROLLERS[cid][1]()  # type: ignore[attr-defined]
        if cid is ControllersID.VISION_DEPTH:
            info = self.latest("depth_camera_info")  # type: ignore[attr-defined]
            if info is None:
                raise BadInput("VisionRGBDFollower needs the depth_camera_info input (camera intrinsics); none received")
            return cid, make_controller(cid, self.config.robot, cfg, intrinsics=CameraIntrinsics(info.fx, info.fy, info.cx, info.cy))  # type: ignore[attr-defined]
        return cid, make_controller(cid, self.config.robot, cfg)  # type: ignore[attr-defined]

    def _track_target(self, goal_handle: Any) -> TrackVisionTargetResult:
        goal: TrackVisionTargetGoal = goal_handle.goal
        if not goal.label:
            return TrackVisionTargetResult(success=False, message="TrackVisionTarget goal needs a label")
        try:
            cid, follower = self._vision_follower()
        except BadInput as exc:
            self.fail_input("depth_camera_info", str(exc))  # type: ignore[attr-defined]
            return TrackVisionTargetResult(success=False, message=str(exc))
        if goal.search_timeout > 0:  # both vision followers search for a lost target
            follower.search.timeout = float(goal.search_timeout)
        pacer = self.node.pacer(1.0 / self.config.loop_rate)  # type: ignore[attr-defined]  # inside the node's ticks on simulated time
        # A new goal preempts the one being followed (as a ROS action server does): an event
        # that fires again must not start a second loop sending commands beside the first.
        self._track_goal = mine = getattr(self, "_track_goal", 0) + 1
        self.get_logger().info("[%s] track_vision_target: following %r with %s", self.component_name, goal.label, cid.value)  # type: ignore[attr-defined]
        self._tracking = True
        last_msg = None  # the detections message the depth follower measured last
        history = PoseHistory()  # where the robot was when the camera took each picture
        try:
            while not goal_handle.is_cancel_requested:
                if self._track_goal != mine:
                    return TrackVisionTargetResult(success=False, message="preempted by a newer goal")
                try:
                    box, msg = self._target_box(goal.label)
                except BadInput as exc:
                    self.fail_input(self._vision_key, str(exc))  # type: ignore[attr-defined]
                    self.publish_stop()  # type: ignore[attr-defined]
                    return TrackVisionTargetResult(success=False, message=str(exc))
                state = self.robot_state(self.config.location_timeout) if cid is ControllersID.VISION_DEPTH else None  # type: ignore[attr-defined]
                if cid is ControllersID.VISION_DEPTH:
                    if state is None:
                        self.publish_stop()  # type: ignore[attr-defined]
                        pacer.wait(lambda: goal_handle.is_cancel_requested)
                        continue
                    pose, vel = state
                    history.add(_stamp_s(self.latest("location")), pose)  # type: ignore[attr-defined]
                    depth = self._depth(msg, follower.config.depth_conversion_factor)
                    seen_from = history.at(_stamp_s(msg)) if msg is not None and _stamp_s(msg) > 0 else None
                    result = follower.compute(pose, self._last_cmd if vel is None else vel, box, depth,  # type: ignore[attr-defined]
                                              new_measurement=msg is not last_msg, seen_from=seen_from)
                    last_msg = msg
                else:
                    result = follower.compute(box, self._last_cmd)  # type: ignore[attr-defined]
                self.publish_result(result)  # type: ignore[attr-defined]
                tracked = self.get_out_topic("tracked_point")  # type: ignore[attr-defined]
                if box is not None and tracked is not None and tracked.msg_type.__name__ == "PoseStamped" and len(result.local_plan):
                    end = np.asarray(result.local_plan)[-1]
                    self.publish(tracked, pose_stamped(end[0], end[1], end[2], self.config.frames.world))  # type: ignore[attr-defined]
                goal_handle.publish_feedback(TrackVisionTargetFeedback(status=result.status.value, target_visible=box is not None))
                if result.status is ControlStatus.LOST:
                    self.publish_stop()  # type: ignore[attr-defined]
                    self.fail_algorithm(cid.value, f"target {goal.label!r} lost")  # type: ignore[attr-defined]
                    self.node.publish_status()  # type: ignore[attr-defined]
                    return TrackVisionTargetResult(success=False, message=f"target {goal.label!r} lost")
                self.health_status.set_healthy()  # type: ignore[attr-defined]
                self.node.publish_status()  # type: ignore[attr-defined]
                pacer.wait(lambda: goal_handle.is_cancel_requested)
            self.publish_stop()  # type: ignore[attr-defined]
            return TrackVisionTargetResult(success=True, message="cancelled")
        finally:
            pacer.close()
            if self._track_goal == mine:
                self._tracking = False


def _stamp_s(msg: Any) -> float:
    """A message's header stamp in seconds (0.0: none)."""
    header = getattr(msg, "header", None)
    return 0.0 if header is None else header.stamp.to_sec()
