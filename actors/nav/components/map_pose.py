"""``MapFramePose``: the robot's pose in the map frame, as tf2 gives it to a Nav2 node.

A localizer (the ``Localizer``) publishes ``map -> odom`` on ``/tf``; the base publishes its
odometry (``odom -> base_link``). This component composes the latest transform with each
odometry message into the pose in the map frame, with the odometry's measured twist, on one
``Odometry`` topic (``/odometry/localized`` in the main job): the ``location`` every navigation
component reads. Nothing is published before the first transform (the stack then waits for its
location) and the component reports SYSTEM_FAILURE naming the missing transform.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from emos.core.component import BaseComponent
from emos.io.topic import Topic

from ..robot import RobotFrames


class MapFramePose(BaseComponent):
    """The robot's pose in the map frame: the latest ``frames.world -> frames.odom`` on ``tf``
    composed with each ``odom`` message, published on ``location``."""

    def __init__(self, *, odom: Topic, tf: Topic, location: Topic, frames: RobotFrames,
                 component_name: str = "map_pose", **kwargs: Any) -> None:
        self.odom_topic, self.tf_topic, self.location_topic = odom, tf, location
        self.map_frames = frames
        super().__init__(component_name=component_name, inputs=[odom, tf], outputs=[location],
                         trigger=odom, run_type="Event", **kwargs)

    def custom_on_activate(self) -> None:
        from ..transforms import TransformTree

        self.tree = TransformTree()
        self.tf_msg: Any = None

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        from ..localization import compose_pose
        from .convert import BadInput, localized_odometry, pose_of, pose_stamped

        frames, tf_topic, odom_topic = self.map_frames, self.tf_topic, self.odom_topic
        tf_msg = self.get_input(tf_topic)
        if tf_msg is not None and tf_msg is not self.tf_msg:
            self.tf_msg = tf_msg
            for problem in self.tree.update(tf_msg):
                self.health_status.set_fail_system(topic_names=[tf_topic.name], message=f"{tf_topic.name}: {problem}")
        odom = msg if msg is not None else self.get_input(odom_topic)
        m = self.tree.lookup(frames.world, frames.odom)
        if odom is None or m is None:
            self.health_status.set_fail_system(topic_names=[tf_topic.name],
                                               message=f"no {frames.world} -> {frames.odom} on {tf_topic.name} yet")
            return
        try:
            x, y, yaw = compose_pose(np.array([m[0, 3], m[1, 3], math.atan2(m[1, 0], m[0, 0])]), pose_of(odom))
        except BadInput as exc:
            self.health_status.set_fail_system(topic_names=[odom_topic.name], message=f"{odom_topic.name}: {exc}")
            return
        self.publish(self.location_topic, localized_odometry(pose_stamped(x, y, yaw, frames.world, stamp=odom.header.stamp),
                                                             odom, frames.robot_base))
        self.health_status.set_healthy()
