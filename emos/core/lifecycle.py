"""The managed-node state machine: Unconfigured -> Inactive -> Active -> Finalized.

Transitions and where they lead (as ROS 2 lifecycle nodes):

=========== ============== ================
transition  from           to
=========== ============== ================
configure   UNCONFIGURED   INACTIVE
activate    INACTIVE       ACTIVE
deactivate  ACTIVE         INACTIVE
cleanup     INACTIVE       UNCONFIGURED
shutdown    any but FINAL. FINALIZED
=========== ============== ================

A transition whose callback raises goes through error processing: if the component's
``on_error`` recovers, the node returns to UNCONFIGURED, otherwise it is FINALIZED.
"""
from __future__ import annotations

from enum import Enum

from emos.errors import EmosError


class LifecycleState(str, Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"
    FINALIZED = "finalized"


class Transition(str, Enum):
    CONFIGURE = "configure"
    ACTIVATE = "activate"
    DEACTIVATE = "deactivate"
    CLEANUP = "cleanup"
    SHUTDOWN = "shutdown"


S, T = LifecycleState, Transition

TABLE: dict[tuple[LifecycleState, Transition], LifecycleState] = {
    (S.UNCONFIGURED, T.CONFIGURE): S.INACTIVE,
    (S.INACTIVE, T.ACTIVATE): S.ACTIVE,
    (S.ACTIVE, T.DEACTIVATE): S.INACTIVE,
    (S.INACTIVE, T.CLEANUP): S.UNCONFIGURED,
    (S.UNCONFIGURED, T.SHUTDOWN): S.FINALIZED,
    (S.INACTIVE, T.SHUTDOWN): S.FINALIZED,
    (S.ACTIVE, T.SHUTDOWN): S.FINALIZED,
}


class InvalidTransition(EmosError, RuntimeError):
    pass


def next_state(state: LifecycleState, transition: Transition | str) -> LifecycleState:
    transition = Transition(transition)
    try:
        return TABLE[(state, transition)]
    except KeyError:
        allowed = [t.value for (s, t) in TABLE if s == state]
        raise InvalidTransition(f"cannot {transition.value} from {state.value}; allowed: {allowed}") from None


def path_to(state: LifecycleState, target: LifecycleState) -> list[Transition]:
    """Transitions that bring ``state`` to ``target`` (for ``emos`` and the supervisor)."""
    order = [S.UNCONFIGURED, S.INACTIVE, S.ACTIVE]
    if target == S.FINALIZED:
        return [] if state == S.FINALIZED else [T.SHUTDOWN]
    if state == S.FINALIZED:
        raise InvalidTransition("a finalized component cannot change state")
    i, j = order.index(state), order.index(target)
    up = [T.CONFIGURE, T.ACTIVATE]
    down = [T.CLEANUP, T.DEACTIVATE]
    if j >= i:
        return up[i:j]
    return [down[k - 1] for k in range(i, j, -1)]
