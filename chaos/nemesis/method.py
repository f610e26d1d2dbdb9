"""Faults a component offers itself: call one of its methods through its control socket.

Some failures only the component can produce faithfully (an algorithm that stops converging, a
model that starts answering garbage). A chaos workload component can expose such a method, and
this nemesis calls it (``execute_method``, the same operation ``emos component call`` uses).
The fault is judged ``recover``: the component must report a failure and then be HEALTHY again
(its fallbacks have to repair it). With ``witness: <topic>`` a message must also arrive on that
topic after the fault (e.g. the alarm an event raises: proof the Monitor is armed).
"""
from __future__ import annotations

from typing import Any

from emos.chaos.history import Record
from emos.chaos.nemesis.base import Nemesis, NemesisError
from emos.core import control as C


class MethodFault(Nemesis):
    kind = "method"
    summary = "call a fault-injecting method of a component (e.g. break its algorithm)"
    expects = "recover"

    def __init__(self, component: str, method: str, args: list | None = None, witness: str | None = None, **params: Any) -> None:
        super().__init__(component=component, method=method, **({"args": args} if args else {}), **({"witness": witness} if witness else {}), **params)
        if not isinstance(component, str) or not component or not isinstance(method, str) or not method:
            raise NemesisError(f"method: component and method must be names, got component={component!r} method={method!r}")
        if params:
            raise NemesisError(f"method: unknown parameter(s) {', '.join(sorted(params))}; known: component, method, args, witness")
        self.component, self.method, self.args = component, method, list(args or [])
        self.witness = witness if not witness or witness.startswith("/") else "/" + witness

    def start(self) -> Record | None:
        assert self.system is not None and self.system.run_dir is not None
        try:
            C.call(self.system.control_socket(self.component), C.EXECUTE_METHOD, C.method_request(self.method, self.args), timeout=2.0)
        except (OSError, ConnectionError, TimeoutError):
            return None  # restarting: nothing to hit now
        record = self._fault(target=self.component, method=self.method, **({"witness": self.witness} if self.witness else {}))
        self.active = None
        return record
