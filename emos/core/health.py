"""Health status: what a component says about how it is doing, sent on ``<component>/status``."""
from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from enum import IntEnum

from emos.msgs.status import ComponentStatus
from emos.msgs.std import Header, Time


class HealthLevel(IntEnum):
    HEALTHY = ComponentStatus.STATUS_HEALTHY
    ALGORITHM_FAILURE = ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL
    COMPONENT_FAILURE = ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL
    SYSTEM_FAILURE = ComponentStatus.STATUS_FAILURE_SYSTEM_LEVEL
    GENERAL = ComponentStatus.STATUS_GENERAL


class Status:
    """``self.health_status`` of a component. Thread-safe: callbacks and action threads set it too."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.level = HealthLevel.HEALTHY
        self.algorithms: list[str] = []
        self.components: list[str] = []
        self.topics: list[str] = []
        self.message = ""
        # Bumped whenever what the status says changes: the node publishes a status after a step
        # only then (and at its heartbeat rate regardless), not after every step.
        self.revision = 0

    def _set(self, level: HealthLevel, algorithms: Sequence[str] = (), components: Sequence[str] = (), topics: Sequence[str] = (), message: str = "") -> None:
        for kind, names in (("algorithm_names", algorithms), ("component_names", components), ("topic_names", topics)):
            if isinstance(names, str) or not all(isinstance(n, str) for n in names):
                raise TypeError(f"{kind} must be a list of str, got {names!r}")
        said = (level, list(algorithms), list(components), list(topics), message)
        with self._lock:
            if said != (self.level, self.algorithms, self.components, self.topics, self.message):
                self.level, self.algorithms, self.components, self.topics, self.message = said
                self.revision += 1

    def set_healthy(self) -> None:
        # Most components say this at every step, and it is nearly always already true: then
        # nothing to check or copy (the general path costs 4-5 us a step straight after a wake-up).
        with self._lock:
            if self.level == HealthLevel.HEALTHY and not (self.message or self.algorithms or self.components or self.topics):
                return
        self._set(HealthLevel.HEALTHY)

    def set_fail_algorithm(self, algorithm_names: Sequence[str] = (), message: str = "") -> None:
        self._set(HealthLevel.ALGORITHM_FAILURE, algorithms=algorithm_names, message=message)

    def set_fail_component(self, component_names: Sequence[str] = (), message: str = "") -> None:
        self._set(HealthLevel.COMPONENT_FAILURE, components=component_names, message=message)

    def set_fail_system(self, topic_names: Sequence[str] = (), message: str = "") -> None:
        self._set(HealthLevel.SYSTEM_FAILURE, topics=topic_names, message=message)

    def set_general(self, message: str = "") -> None:
        self._set(HealthLevel.GENERAL, message=message)

    @property
    def is_healthy(self) -> bool:
        return self.level == HealthLevel.HEALTHY

    @property
    def is_algorithm_fail(self) -> bool:
        return self.level == HealthLevel.ALGORITHM_FAILURE

    @property
    def is_component_fail(self) -> bool:
        return self.level == HealthLevel.COMPONENT_FAILURE

    @property
    def is_system_fail(self) -> bool:
        return self.level == HealthLevel.SYSTEM_FAILURE

    def to_msg(self, lifecycle_state: str = "") -> ComponentStatus:
        with self._lock:
            return ComponentStatus(
                # Wall time on purpose, even in a simulated run: the supervisor tells a status of
                # this incarnation from an earlier one's by comparing it with the wall time the
                # process started (supervisor/fallback_driver.py). Data stamps use emos.core.clock.
                header=Header(stamp=Time.now()),
                status=int(self.level),
                src_algorithms=self.algorithms,
                src_components=self.components,
                src_topics=self.topics,
                message=self.message,
                lifecycle_state=lifecycle_state,
                pid=os.getpid(),
            )

    def __call__(self) -> ComponentStatus:
        return self.to_msg()

    def __repr__(self) -> str:
        return f"Status({self.level.name})"
