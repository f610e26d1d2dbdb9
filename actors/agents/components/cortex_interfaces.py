"""Cortex's action interface: ``<component>/run_task`` takes a task in words, reports each plan,
step and outcome as feedback, and ends with whether the task succeeded and the model's summary.
The messages are registered under EmbodiedAgents' package name, as the VLA's are."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type

_PKG = "automatika_embodied_agents"


@message_type(_PKG, name="CortexTaskGoal")
class CortexTaskGoal(Message):
    task: str = F.string()


@message_type(_PKG, name="CortexTaskFeedback")
class CortexTaskFeedback(Message):
    kind: str = F.string()  # plan, refused, step, outcome, replan, done
    text: str = F.string()


@message_type(_PKG, name="CortexTaskResult")
class CortexTaskResult(Message):
    success: bool = F.boolean()
    answer: str = F.string()
    message: str = F.string()
    steps: int = F.integer(bits=32)
    replans: int = F.integer(bits=32)
    report: str = F.string()  # the whole TaskReport as JSON
