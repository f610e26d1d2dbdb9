"""Pristine copies of components for threaded mode, where no zygote keeps a fresh image.

A restart in threaded mode must start from the component as the recipe defined it, as a
restarted process does (it is forked from the zygote's image). So the supervisor deep-copies
each threaded component before it ever runs, and copies that copy at each start.

Locks are what stop a plain ``copy.deepcopy``: nearly every component holds some from its
definition on (its health status, rate-limited logs, caches), and a lock cannot be copied
("cannot pickle '_thread.lock' object"). A copy of a component needs locks of its own anyway,
new and unheld, so the copy is made with a memo that maps every lock reachable from the
component to a new one, and every method bound to such a lock (``threading.Condition`` keeps
its lock's ``acquire`` and ``release``; ``Event``, ``Semaphore`` and ``queue.Queue`` build on
it) to the same method of the new lock. A lock shared by several objects stays shared in the
copy. What else cannot be copied (an open socket or file) is named once; restarts of that
component then reuse the object.
"""
from __future__ import annotations

import copy
import gc
import logging
import threading
import types
from typing import Any, TypeVar

log = logging.getLogger("emos.supervisor")

T = TypeVar("T")

_LOCK = type(threading.Lock())
_RLOCK = type(threading.RLock())
# deepcopy shares these instead of copying them, so the walk does not look inside either: a
# function's globals are a whole module.
_SHARED = (type, types.ModuleType, types.FunctionType, types.BuiltinFunctionType, types.CodeType,
           str, bytes, int, float, complex, type(None))
WALK_LIMIT = 1_000_000  # objects: past this the copy goes on without fresh locks (and may fail, said once)


def _lock_memo(root: Any) -> dict[int, Any]:
    """A deepcopy memo: id of each lock (and lock method) reachable from ``root`` -> its new counterpart."""
    memo: dict[int, Any] = {}

    def fresh(lock: Any) -> Any:
        new = memo.get(id(lock))
        if new is None:
            new = memo[id(lock)] = threading.RLock() if isinstance(lock, _RLOCK) else threading.Lock()
        return new

    seen: set[int] = set()
    stack = [root]
    while stack and len(seen) < WALK_LIMIT:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (_LOCK, _RLOCK)):
            fresh(obj)
        elif isinstance(obj, types.BuiltinMethodType) and isinstance(obj.__self__, (_LOCK, _RLOCK)):
            memo[id(obj)] = getattr(fresh(obj.__self__), obj.__name__)
        elif not isinstance(obj, _SHARED):
            stack.extend(gc.get_referents(obj))
    return memo


def _uncopyable_attribute(obj: Any) -> str:
    """The first attribute of ``obj`` that cannot be copied, for the warning."""
    for key, value in getattr(obj, "__dict__", {}).items():
        try:
            copy.deepcopy(value, _lock_memo(value))
        except Exception:  # noqa: BLE001 - any failure names the attribute
            return key
    return "?"


def pristine_copy(component: T) -> T:
    """A deep copy of ``component`` with new locks; the component itself if it cannot be
    copied (said here, once per call: the supervisor makes this copy once per component)."""
    try:
        return copy.deepcopy(component, _lock_memo(component))
    except Exception as exc:  # noqa: BLE001 - whatever stops the copy, restarts fall back to reuse
        name = getattr(component, "component_name", type(component).__name__)
        log.warning("[%s] cannot copy the component for restarts in threaded mode (attribute %r: %s): "
                    "a restart reuses the same object, with the state it had", name, _uncopyable_attribute(component), exc)
        return component
