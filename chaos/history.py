"""The history of a chaos run: every fault, every observation, on one clock.

Jepsen's idea: the nemesis and the observers only *record*; checkers judge the history after the
run. Times are seconds on ``time.monotonic()`` since the run started, so a fault and the status
snapshot that shows its recovery can be compared directly.
"""
from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from typing import Any

from attrs import asdict, define, field


@define
class Record:
    t: float
    kind: str  # "fault", "fault_end", "status", "event" (the supervisor's), "note", "exit"
    name: str  # the nemesis for faults, the component for status, free text otherwise
    detail: dict[str, Any] = field(factory=dict)


class History:
    """Thread-safe, append-only list of :class:`Record` (nemeses and the observer run in threads)."""

    def __init__(self) -> None:
        self.t0 = time.monotonic()
        self.wall_t0 = time.time()
        self._records: list[Record] = []
        self._lock = threading.Lock()

    def now(self) -> float:
        return time.monotonic() - self.t0

    def add(self, kind: str, name: str, **detail: Any) -> Record:
        record = Record(round(self.now(), 4), kind, name, detail)
        with self._lock:
            self._records.append(record)
        return record

    def records_event(self, t: float, event: str, detail: dict[str, Any], kind: str = "event") -> Record:
        """A record observed after the fact at its own time ``t``: a supervisor event (kind
        ``event``, name = the event), or the moment the workload finished (kind ``exit``)."""
        record = Record(round(t, 4), kind, event, detail)
        with self._lock:
            self._records.append(record)
        return record

    def __iter__(self) -> Iterator[Record]:
        with self._lock:
            return iter(list(self._records))

    def of(self, kind: str) -> list[Record]:
        return [r for r in self if r.kind == kind]

    def to_json(self) -> str:
        return json.dumps({"wall_t0": self.wall_t0, "records": [asdict(r) for r in self]}, default=str)
