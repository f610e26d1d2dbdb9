"""A component's action, offered as an input of the web UI (``planner.ui_main_action_input``)."""
from __future__ import annotations

from typing import Any

from attrs import define


@define(frozen=True)
class ActionInput:
    """The action server ``name`` of ``component`` and its goal, feedback and result types.
    Given to ``launcher.enable_ui(inputs=[...])``, the page sends goals to it and shows the
    feedback and the result."""

    name: str
    goal_type: Any
    feedback_type: Any
    result_type: Any
    component: str = ""
