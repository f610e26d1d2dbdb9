"""Goals given in pixels: a ``Detections`` or ``PointsOfInterest`` message (from a VLM or a
detector on an RGBD stream) as a world goal for the :class:`Planner`.

The message carries pixel coordinates and, when it came from an RGBD input, the aligned depth
image (``msg.image``). The conversion:

1. the pixel target: the centre of the best detection (highest score), or every point of interest;
2. its depth: the median of the valid depths around it (the central half of the box, or a
   small window around each point), so holes and background at the edges do not count;
3. the camera intrinsics (``depth_camera_info``) back-project it into the camera's optical frame;
4. the transform tree (``tf``) places the camera (the depth image's ``frame_id``) on the robot
   base, and the robot's location places the base in the world. Several points are averaged.

Anything missing or unusable raises :class:`BadInput` saying what and where; the caller reports
it and keeps its current goal.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from emos.msgs import intelligence as I
from emos.msgs.sensor import CameraInfo, Image

from ..controllers.vision_common import CameraIntrinsics, median_depth
from ..transforms import TransformTree
from .convert import BadInput

__all__ = ["PIXEL_GOAL_TYPES", "PixelGoals", "is_pixel_goal", "pixel_targets", "depth_in_metres", "intrinsics_of",
           "pixel_goal_in_world", "camera_on_base"]

PIXEL_GOAL_TYPES = ("Detections", "PointsOfInterest")
#: depth encodings: 32FC1 is metres (REP 118); integer ones are the camera's raw units
INTEGER_DEPTH = ("16UC1", "mono16")
POINT_WINDOW = 3.0  # half size (px) of the window around a point of interest whose depths are used


def is_pixel_goal(msg: Any) -> bool:
    return isinstance(msg, (I.Detections, I.PointsOfInterest))


def pixel_targets(msg: Any, where: str) -> list[tuple[float, float, float, float]]:
    """(u, v, half width, half height) of the depth windows to measure: the best box's centre
    (its central half), or each point of interest (a small window)."""
    if isinstance(msg, I.Detections):
        boxes = np.asarray(msg.boxes, dtype=np.float64).reshape(-1, 4)
        if len(boxes) == 0:
            raise BadInput(f"{where}: the Detections message holds no detection")
        scores = np.asarray(msg.scores, dtype=np.float64)
        order = np.argsort(-np.where(np.isfinite(scores), scores, -np.inf), kind="stable") if len(scores) == len(boxes) else range(len(boxes))
        for i in order:
            x1, y1, x2, y2 = boxes[i]
            if np.all(np.isfinite(boxes[i])) and x2 > x1 and y2 > y1:
                return [(0.5 * (x1 + x2), 0.5 * (y1 + y2), 0.25 * (x2 - x1), 0.25 * (y2 - y1))]
        raise BadInput(f"{where}: no detection has a finite box with x2 > x1 and y2 > y1 (boxes {boxes.tolist()})")
    if isinstance(msg, I.PointsOfInterest):
        points = np.asarray(msg.points, dtype=np.float64).reshape(-1, 2)
        points = points[np.all(np.isfinite(points), axis=1)]
        if len(points) == 0:
            raise BadInput(f"{where}: the PointsOfInterest message holds no finite point")
        return [(float(u), float(v), POINT_WINDOW, POINT_WINDOW) for u, v in points]
    raise BadInput(f"{where}: expected Detections or PointsOfInterest, got {type(msg).__name__}")


def depth_in_metres(image: Image | None, conversion_factor: float, where: str) -> np.ndarray:
    """The depth image as metres: 32FC1 as it is, 16UC1/mono16 times ``conversion_factor``."""
    if image is None:
        raise BadInput(f"{where}: the message carries no depth image; give the detector or VLM an RGBD input "
                       "(the depth travels in the message's image)")
    if image.encoding == "32FC1":
        return np.asarray(image.to_numpy(), dtype=np.float64)
    if image.encoding in INTEGER_DEPTH:
        return np.asarray(image.to_numpy(), dtype=np.float64) * conversion_factor
    raise BadInput(f"{where}: the attached image is {image.encoding!r}, not a depth image (32FC1, 16UC1 or mono16); "
                   "give the detector or VLM an RGBD input")


def intrinsics_of(info: CameraInfo | None, where: str) -> CameraIntrinsics:
    if info is None:
        raise BadInput(f"{where}: no CameraInfo received yet, so the camera intrinsics are unknown")
    try:
        return CameraIntrinsics(info.fx, info.fy, info.k[2], info.k[5])
    except ValueError as exc:
        raise BadInput(f"{where}: unusable camera intrinsics K={np.asarray(info.k).tolist()} ({exc})") from None


def pixel_goal_in_world(msg: Any, depth: np.ndarray, intrinsics: CameraIntrinsics, base_from_camera: np.ndarray,
                        robot_pose: np.ndarray, where: str) -> np.ndarray:
    """(x, y) in the frame of ``robot_pose`` of the pixel target(s) of ``msg``.

    ``base_from_camera`` (4x4) maps the camera's optical frame (x right, y down, z forward)
    into the robot base frame; ``robot_pose`` is the base's (x, y, yaw).
    """
    h, w = depth.shape[:2]
    points = []
    for u, v, half_w, half_h in pixel_targets(msg, where):
        if not (0 <= u < w and 0 <= v < h):
            raise BadInput(f"{where}: pixel ({u:.1f}, {v:.1f}) is outside the {w}x{h} depth image")
        z = median_depth(depth, u, v, half_w, half_h)
        if z is None:
            raise BadInput(f"{where}: no valid depth (finite, > 0) around pixel ({u:.1f}, {v:.1f})")
        points.append(intrinsics.back_project(u, v, z))
    optical = np.mean(np.asarray(points), axis=0)
    in_base = base_from_camera[:3, :3] @ optical + base_from_camera[:3, 3]
    x, y, yaw = (float(v) for v in robot_pose[:3])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * in_base[0] - s * in_base[1], y + s * in_base[0] + c * in_base[1]])


def camera_on_base(tree: TransformTree, base_frame: str, camera_frame: str, where: str) -> np.ndarray:
    """The camera's transform on the base (4x4) from the transform tree."""
    if not camera_frame:
        raise BadInput(f"{where}: the depth image has no frame_id, so the camera's place on the robot is unknown")
    try:
        matrix = tree.lookup(base_frame, camera_frame)
    except ValueError as exc:  # a malformed tree (a cycle)
        raise BadInput(f"{where}: {exc}") from None
    if matrix is None:
        raise BadInput(f"{where}: no transform from {base_frame!r} to the camera frame {camera_frame!r} in the transform tree")
    return matrix


class PixelGoals:
    """Mixin of the :class:`Planner`: turns a pixel goal on ``goal_point`` into a world goal with
    the ``depth_camera_info``, ``tf`` and ``location`` inputs (see the module doc)."""

    def pixel_goal(self, msg: Any) -> np.ndarray | None:
        """(x, y) of a Detections/PointsOfInterest goal; None (reported as a SYSTEM failure naming
        the topic at fault) when it cannot be converted. Each message is converted once, with the
        robot's pose when it arrives; a message seen before returns None."""
        if msg is getattr(self, "_pixel_goal_msg", None):
            return None
        self._pixel_goal_msg = msg
        name = self.topic_name  # type: ignore[attr-defined]
        where = f"goal_point {name('goal_point')} ({type(msg).__name__})"
        key = "goal_point"
        try:
            pixel_targets(msg, where)  # a message that names no pixel is reported as such first
            depth = depth_in_metres(getattr(msg, "image", None), self.config.depth_conversion_factor, where)  # type: ignore[attr-defined]
            key = "depth_camera_info"
            info = self.latest(key)  # type: ignore[attr-defined]
            intrinsics = intrinsics_of(info, f"depth_camera_info {name(key)}")
            if info.width and info.height and (info.width, info.height) != (depth.shape[1], depth.shape[0]):
                raise BadInput(f"depth_camera_info {name(key)}: the camera is {info.width}x{info.height} but the depth "
                               f"image of {where} is {depth.shape[1]}x{depth.shape[0]}")
            key = "tf"
            camera = camera_on_base(self._transform_tree(), self.config.frames.robot_base,  # type: ignore[attr-defined]
                                    msg.image.header.frame_id, f"tf {name(key)}")
            key = "location"
            state = self.robot_state()  # type: ignore[attr-defined]  # reports a missing or bad location itself
            if state is None:
                return None
            key = "goal_point"
            goal = pixel_goal_in_world(msg, depth, intrinsics, camera, state[0], where)
        except BadInput as exc:
            text = str(exc) if key == "goal_point" else f"{exc} (needed for the goal on {where})"
            self.fail_input(key, f"{text}; the current goal is kept")  # type: ignore[attr-defined]
            return None
        self.get_logger().info("[%s] goal from %s: (%.2f, %.2f) in %s", self.component_name, where,  # type: ignore[attr-defined]
                               goal[0], goal[1], self.config.frames.world)  # type: ignore[attr-defined]
        return goal

    def _transform_tree(self) -> TransformTree:
        """The transform tree, fed with the latest ``tf`` message (kept across messages, so
        transforms published in separate batches accumulate)."""
        tree = getattr(self, "_tf_tree", None)
        if tree is None:
            tree = self._tf_tree = TransformTree()
        msg = self.latest("tf")  # type: ignore[attr-defined]
        if msg is not None and msg is not getattr(self, "_tf_msg", None):
            self._tf_msg = msg
            problems = tree.update(msg)
            if problems:
                self.fail_input("tf", f"tf {self.topic_name('tf')}: skipped transforms: {'; '.join(problems)}")  # type: ignore[attr-defined]
        return tree
