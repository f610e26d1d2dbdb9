"""Sensor faults: a component's published topic stalls, slows, carries NaN/inf or truncated
scans, freezes, or (odometry) jumps, for the fault's duration.

The fault is applied inside the publishing component (``emos.core.faults``), switched on and off
through its control socket, so subscribers receive exactly what a broken sensor would send.
``stale`` faults (stall) are the ones after which consumers must treat their input as stale:
the checker verifies that the watched command topic goes to zero within the consumer's
timeout plus one control period.
"""
from __future__ import annotations

from typing import Any

from emos.chaos.history import Record
from emos.chaos.nemesis.base import Nemesis, NemesisError
from emos.core import control as C
from emos.core.faults import MODES


class SensorFault(Nemesis):
    kind = "sensor"
    summary = "a published topic stalls, slows, gets NaN/inf or truncated scans, freezes or (odometry) jumps"
    expects = "healthy"

    def __init__(self, component: str, topic: str, mode: str, target: str | None = None, **params: Any) -> None:
        super().__init__(component=component, topic=topic, mode=mode, **({"target": target} if target else {}), **params)
        if mode not in MODES:
            raise NemesisError(f"sensor: unknown mode {mode!r}; modes: {', '.join(MODES)}")
        self.component, self.topic, self.mode, self.fault_params = component, topic if topic.startswith("/") else "/" + topic, mode, params
        self.target = target or component

    def _call(self, op: str, **req: Any) -> Any:
        assert self.system is not None and self.system.run_dir is not None
        return C.call(self.system.control_socket(self.component), op, req, timeout=2.0)

    def start(self) -> Record | None:
        try:
            self._call(C.INJECT_FAULT, topic=self.topic, mode=self.mode, params=self.fault_params)
        except (OSError, ConnectionError, TimeoutError):
            return None  # the component is restarting: nothing to hit now
        return self._fault(target=self.target, component=self.component, topic=self.topic, mode=self.mode, stale=self.mode == "stall")

    def stop(self) -> None:
        if self.active is not None:
            try:
                self._call(C.CLEAR_FAULT, topic=self.topic)
            except (OSError, ConnectionError, TimeoutError):
                pass  # a restarted component starts without faults
        super().stop()
