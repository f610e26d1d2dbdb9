"""What a run offers, read from the run's own answers: the components in the supervisor's tree,
and the services and actions each one lists in its ``info`` answer.

Every reader of a running system uses these: the CLI (``emos component list``, ``emos service
list``, ``emos action list``) and components that plan with what the run serves (Cortex). The
answers come over sockets from other processes, so they are read defensively: a malformed node
or entry is skipped, and names are cut to printable text of bounded length. How a client then
loads an interface's types is its own choice (the CLI may import a module of the ``emos``
package; Cortex only resolves registered types); this module imports nothing by name.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any, TypeVar, overload

import attrs

from emos.core.services import ACTION_ROLES, SERVICE_ROLES
from emos.msgs.registry import UnknownMessageType, resolve

__all__ = ["KINDS", "Interface", "component_workers", "interfaces_of", "printable", "supervisor_nodes", "tree_nodes", "worker_nodes"]

# The types of each kind of interface, in order ("request", "response" for a service).
KINDS: dict[str, tuple[str, ...]] = {"service": SERVICE_ROLES, "action": ACTION_ROLES}


def printable(value: Any, limit: int = 200) -> str:
    """``value`` as printable text of at most ``limit`` characters (a peer is not trusted to
    send clean strings: no control characters reach a terminal, a log or a model prompt)."""
    return "".join(ch for ch in str(value)[:limit] if ch.isprintable())


def tree_nodes(tree: Any) -> Iterator[dict[str, Any]]:
    """Every node of a supervisor tree (the ``tree`` of the supervisor's ``tree`` answer, maybe
    another host's), depth first in start order; nodes that are not maps are skipped, with their
    subtrees, and a ``children`` that is not a list counts as none."""
    if not isinstance(tree, dict):
        return
    yield tree
    children = tree.get("children")
    for child in children if isinstance(children, list) else []:
        yield from tree_nodes(child)


def worker_nodes(tree: Any) -> list[dict[str, Any]]:
    """The worker (component) nodes of a supervisor tree, depth first in start order."""
    return [node for node in tree_nodes(tree) if node.get("kind") == "worker"]


def supervisor_nodes(tree: Any) -> list[dict[str, Any]]:
    """The supervisor (group) nodes of a supervisor tree, the root included."""
    return [node for node in tree_nodes(tree) if node.get("kind") == "supervisor" or "children" in node]


def component_workers(tree: Any) -> list[str]:
    """The worker (component) names of a supervisor tree, depth first in start order."""
    return [node["name"] for node in worker_nodes(tree) if isinstance(node.get("name"), str)]


@attrs.define(frozen=True)
class Interface:
    """One service or action of a component, as its ``info`` answer describes it."""

    kind: str  # "service" or "action"
    name: str  # e.g. "planner/save_plan_to_file" (no leading slash)
    component: str
    serving: bool  # served now (a component serves only while active)
    types: dict[str, str]  # role ("request", "goal", ...) -> canonical type name
    modules: dict[str, str]  # role -> module that defines the type ("" when unknown)

    @property
    def shown(self) -> str:
        return "/" + self.name

    def registered_types(self) -> tuple[type, ...] | None:
        """The message classes of the types, in role order, resolved among the types this
        process has registered (never imported by name); None when one is not known here."""
        out = []
        for role in KINDS[self.kind]:
            try:
                out.append(resolve(self.types[role]))
            except UnknownMessageType:
                return None
        return tuple(out)


_I = TypeVar("_I", bound=Interface)


@overload
def interfaces_of(component: str, kind: str, entries: Any) -> list[Interface]: ...
@overload
def interfaces_of(component: str, kind: str, entries: Any, cls: type[_I]) -> list[_I]: ...
def interfaces_of(component: str, kind: str, entries: Any, cls: type[Interface] = Interface) -> list[Any]:
    """The ``kind`` ("service" or "action") interfaces in ``entries``, the ``services`` or
    ``actions`` list of ``component``'s ``info`` answer (see
    :func:`emos.core.services.describe_interfaces`), as ``cls`` objects. An entry without a
    name or without all its types cannot be called and is skipped."""
    roles = KINDS[kind]
    out: list[Interface] = []
    if not isinstance(entries, list):
        return out
    for entry in entries:
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            continue
        types, modules = {}, {}
        for role in roles:
            spec = entry.get(role)
            if isinstance(spec, dict) and isinstance(spec.get("type"), str):
                types[role] = printable(spec["type"])
                modules[role] = printable(spec.get("module", ""))
        if len(types) == len(roles):
            out.append(cls(kind, printable(entry["name"]).strip("/"), component, bool(entry.get("serving")), types, modules))
    return out
