"""Request and response types of common services (std_srvs), and the goal, feedback and result
types of the actions shared with ROS 2 (test_msgs Fibonacci).

A ROS 2 service ``pkg/srv/X`` is registered as ``pkg/msg/X_Request`` and ``pkg/msg/X_Response``;
an action ``pkg/action/X`` as ``pkg/msg/X_Goal``, ``pkg/msg/X_Feedback`` and ``pkg/msg/X_Result``
(what the ROS 2 bridge, :mod:`emos.interop.ros2.services` and ``.actions``, looks for).
"""
from __future__ import annotations

import numpy as np

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type


@message_type("std_srvs", name="Trigger_Request")
class TriggerRequest(Message):
    pass


@message_type("std_srvs", name="Trigger_Response")
class TriggerResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()


@message_type("std_srvs", name="SetBool_Request")
class SetBoolRequest(Message):
    data: bool = F.boolean()


@message_type("std_srvs", name="SetBool_Response")
class SetBoolResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()


# test_msgs/action/Fibonacci: the action ROS 2's own tests use, and the one both sides have (the
# Jazzy wheels bring test_msgs). The sequence is int32 on both sides.
@message_type("test_msgs", name="Fibonacci_Goal")
class FibonacciGoal(Message):
    order: int = F.integer(bits=32)


@message_type("test_msgs", name="Fibonacci_Feedback")
class FibonacciFeedback(Message):
    sequence: np.ndarray = F.array(dtype="int32", ndim=1)


@message_type("test_msgs", name="Fibonacci_Result")
class FibonacciResult(Message):
    sequence: np.ndarray = F.array(dtype="int32", ndim=1)
