"""The VLA component's action interface and robot description helpers.

The action (``<component>/vision_language_action``) takes a task instruction and reports the
timestep as feedback; its messages are registered under EmbodiedAgents' package name. Joint
limits come from a URDF (``<limit lower upper>`` of revolute and prismatic joints) or from the
config, and every command is capped to them.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type


@message_type("automatika_embodied_agents", name="VisionLanguageActionGoal")
class VisionLanguageActionGoal(Message):
    task: str = F.string()


@message_type("automatika_embodied_agents", name="VisionLanguageActionFeedback")
class VisionLanguageActionFeedback(Message):
    timestep: int = F.integer(bits=32)
    message: str = F.string()


@message_type("automatika_embodied_agents", name="VisionLanguageActionResult")
class VisionLanguageActionResult(Message):
    success: bool = F.boolean()
    timesteps: int = F.integer(bits=32)
    message: str = F.string()


def joint_limits_from_urdf(path: str | Path) -> dict[str, tuple[float, float]]:
    """``{joint name: (lower, upper)}`` of the limited joints of a URDF file."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"robot_urdf_file {str(path)!r} does not exist")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"robot_urdf_file {str(path)!r} is not valid XML: {exc}") from None
    limits: dict[str, tuple[float, float]] = {}
    for joint in root.iter("joint"):
        if joint.get("type") not in ("revolute", "prismatic"):
            continue
        limit = joint.find("limit")
        name = joint.get("name")
        lower_text = limit.get("lower") if limit is not None else None
        upper_text = limit.get("upper") if limit is not None else None
        if name is None or lower_text is None or upper_text is None:
            continue
        try:
            lower, upper = float(lower_text), float(upper_text)
        except ValueError:
            raise ValueError(f"robot_urdf_file {str(path)!r}: joint {name!r} has non-numeric limits") from None
        if lower > upper:
            raise ValueError(f"robot_urdf_file {str(path)!r}: joint {name!r} has lower {lower} > upper {upper}")
        limits[name] = (lower, upper)
    return limits
