"""The Memory tools as OpenAI-style specs: what Cortex (or an LLM) is offered. Each is a public
method of the ``Memory`` component with the same name and arguments."""
from __future__ import annotations

from ..types import ToolSpec

_NUM = {"type": "number"}


def _spec(name: str, description: str, properties: dict, required: tuple[str, ...] = ()) -> ToolSpec:
    return ToolSpec(name=name, description=description,
                    parameters={"type": "object", "properties": properties, "required": list(required)})


MEMORY_TOOLS: dict[str, ToolSpec] = {s.name: s for s in (
    _spec("semantic_search", "Search the robot's memories by meaning (what it saw, heard and did).",
          {"query": {"type": "string", "minLength": 1}, "n_results": {"type": "integer", "minimum": 1, "maximum": 50}}, ("query",)),
    _spec("spatial_query", "What the robot remembers within radius metres of the map position (x, y).",
          {"x": _NUM, "y": _NUM, "radius": _NUM, "n_results": {"type": "integer", "minimum": 1, "maximum": 200}}, ("x", "y", "radius")),
    _spec("temporal_query", "What the robot remembers between since_s and until_s seconds ago (until_s=0: now).",
          {"since_s": _NUM, "until_s": _NUM, "n_results": {"type": "integer", "minimum": 1, "maximum": 200}}, ("since_s",)),
    _spec("episode_summary", "A summary of what happened in the last since_s seconds.", {"since_s": _NUM}, ("since_s",)),
    _spec("locate", "Where and when the robot last saw an object (a detection label, e.g. 'cup').",
          {"label": {"type": "string", "minLength": 1}}, ("label",)),
    _spec("recall", "Everything the robot remembers about a subject: matching memories with where and when.",
          {"subject": {"type": "string", "minLength": 1}}, ("subject",)),
    _spec("body_status", "The robot's own state now: position, battery, faults of its components.", {}),
)}
