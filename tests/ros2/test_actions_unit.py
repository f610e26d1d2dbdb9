"""The action type mapping of the ROS 2 bridge (emos/interop/ros2/actions.py), without processes."""
from __future__ import annotations

import array
from types import SimpleNamespace

import numpy as np
import pytest

from emos.interop.ros2.actions import emos_types_of, ros_action_of, to_emos, to_ros
from emos.msgs.srv import FibonacciFeedback, FibonacciGoal, FibonacciResult

pytestmark = pytest.mark.unit


def test_a_ros2_action_type_maps_to_its_three_emos_types_and_back():
    assert emos_types_of("test_msgs/action/Fibonacci") == (FibonacciGoal, FibonacciFeedback, FibonacciResult)
    assert ros_action_of("test_msgs/msg/Fibonacci_Goal", "test_msgs/msg/Fibonacci_Feedback", "test_msgs/msg/Fibonacci_Result") == \
        "test_msgs/action/Fibonacci"


@pytest.mark.parametrize("ros_action", ["test_msgs/action/NestedMessage", "test_msgs/srv/Fibonacci", "Fibonacci", ""])
def test_an_action_type_emos_lacks_has_no_counterpart(ros_action):
    assert emos_types_of(ros_action) is None


@pytest.mark.parametrize("names", [
    ("test_msgs/msg/Fibonacci_Goal", "test_msgs/msg/Fibonacci_Feedback", "other/msg/Fibonacci_Result"),  # not one set
    ("test_msgs/msg/Fibonacci_Request", "test_msgs/msg/Fibonacci_Feedback", "test_msgs/msg/Fibonacci_Result"),
    ("nav/PlanGoal", "nav/PlanFeedback", "nav/PlanResult"),  # no package/msg/ form
])
def test_emos_action_types_that_are_not_a_ros2_set_have_no_counterpart(names):
    assert ros_action_of(*names) is None


class _RosLike:
    """Stands in for an rclpy message class: plain attributes (the rclpy classes themselves are
    used by tests/ros2/test_actions.py, in the bridge process, not loaded into pytest's)."""

    order = 0
    sequence: tuple = ()


def test_goal_feedback_and_result_copy_field_by_field_both_ways():
    assert to_ros(FibonacciGoal(order=7), _RosLike).order == 7
    ros = to_ros(FibonacciFeedback(sequence=np.array([0, 1, 1, 2], np.int32)), _RosLike)
    assert ros.sequence == [0, 1, 1, 2] and all(type(v) is int for v in ros.sequence)  # rclpy's setters want ints
    back = to_emos(SimpleNamespace(sequence=array.array("i", [0, 1, 1, 2, 3])), FibonacciResult)
    assert back.sequence.dtype == np.int32 and back.sequence.tolist() == [0, 1, 1, 2, 3]
    with pytest.raises(Exception, match="order"):  # ours validates: an int32 out of range is refused by name
        to_emos(SimpleNamespace(order=2**40), FibonacciGoal)
