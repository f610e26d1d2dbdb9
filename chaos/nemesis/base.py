"""What every nemesis is: a small, seeded fault with a start and a stop.

``start()`` injects the fault and returns the fault record (or None when there was nothing to
hit); ``stop()`` undoes whatever lasts (a stopped process is continued, a proxy healed). The
runner calls ``stop()`` after the fault's duration, when the run ends, and on Ctrl-C, so a
nemesis never outlives its run. ``expects`` says how the checker judges recovery:

* ``restart``: the target component comes back as a new process and reports HEALTHY;
* ``healthy``: the target keeps (or goes back to) HEALTHY once the fault stops;
* ``zygote``: a new zygote takes over (the next restart still works);
* ``none``: nothing to recover (e.g. faults meant to escalate).
"""
from __future__ import annotations

import random
from typing import Any, ClassVar

from emos.chaos.history import History, Record
from emos.chaos.target import RunningSystem
from emos.errors import ConfigError


class NemesisError(ConfigError):
    """A nemesis was configured wrongly (named in the message)."""


class Nemesis:
    kind: ClassVar[str] = "nemesis"
    summary: ClassVar[str] = ""
    expects: ClassVar[str] = "none"

    def __init__(self, **params: Any) -> None:
        self.params = params
        self.system: RunningSystem | None = None
        self.history: History | None = None
        self.rng = random.Random(0)
        self.active: Record | None = None

    def bind(self, system: RunningSystem, history: History, rng: random.Random) -> None:
        self.system, self.history, self.rng = system, history, rng

    def start(self) -> Record | None:
        raise NotImplementedError

    def stop(self) -> None:
        """Undo a lasting fault; the base has nothing to undo."""
        if self.active is not None and self.history is not None:
            self.history.add("fault_end", self.kind, fault_t=self.active.t)
        self.active = None

    def _fault(self, **detail: Any) -> Record:
        assert self.history is not None
        self.active = self.history.add("fault", self.kind, expects=self.expects, **detail)
        return self.active

    def describe(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{self.kind}({args})"


class Compose(Nemesis):
    """Several nemeses started and stopped together (e.g. a hang while a sensor stalls)."""

    kind = "compose"
    summary = "start several nemeses at once"

    def __init__(self, parts: list[Nemesis]) -> None:
        super().__init__(parts=[p.describe() for p in parts])
        if not parts:
            raise NemesisError("compose: give at least one nemesis")
        self.parts = parts

    def bind(self, system: RunningSystem, history: History, rng: random.Random) -> None:
        super().bind(system, history, rng)
        for p in self.parts:
            p.bind(system, history, rng)

    def start(self) -> Record | None:
        records = [p.start() for p in self.parts]
        return next((r for r in records if r is not None), None)

    def stop(self) -> None:
        for p in self.parts:
            p.stop()
