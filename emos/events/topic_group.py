"""The events a topic's messages are checked against, evaluated together.

With a hundred events armed on one topic, the Monitor's cost per message is what decides how
much it competes with the robot's components for the CPU. One generated function evaluates all
the topic's conditions (:func:`~emos.events.compiled.compile_group`), and only the events whose
value matters are observed: a plain event whose condition is not true cannot fire, so it is
skipped; an ``on_change`` event sees every known value (it keeps its edge state).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

from emos.events.compiled import compile_group
from emos.events.event import EventTracker


class TopicEvents:
    def __init__(self, indices: Sequence[int], trackers: Sequence[EventTracker]):
        self.indices = list(indices)
        self.whole = [i for i in self.indices if trackers[i].whole_topic]
        self.conditions = [i for i in self.indices if not trackers[i].whole_topic]
        self._edge = [trackers[i].on_change for i in self.conditions]
        self._evaluate = compile_group([trackers[i].tree for i in self.conditions]) if self.conditions else None

    def values(self, fresh: Callable[[str], Any], trigger: str) -> Iterator[tuple[int, bool | None]]:
        """``(event index, condition value)`` of the condition events worth observing. Raises what
        a condition raises: the caller then checks the events one by one, each error apart."""
        if self._evaluate is None:
            return iter(())
        values = self._evaluate(fresh, trigger)
        return ((i, v) for i, v, edge in zip(self.conditions, values, self._edge) if v is True or edge)
