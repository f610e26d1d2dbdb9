"""A component's services and actions, and their message types, for ``emos service list/call``
and ``emos action list/send_goal``.

A component says in its ``info`` answer (its control socket) which services and actions it
serves, whether they are up (only while it is active), and for each type its canonical name and
the module that defines it. This process has imported only ``emos.msgs``; a type defined
elsewhere in EMOS (the navigation interfaces in ``emos.actors.nav.components.interfaces``) is
loaded by importing its module, but only a module of the ``emos`` package: the answer comes
from a socket, and nothing it says may make us import other code. A type that a recipe defines
itself is registered with ``--import MODULE`` (as for ``emos record``); otherwise the error
says so.

Names: ``planner/save_plan_to_file``, ``/planner/save_plan_to_file`` and, for component
``planner``, ``save_plan_to_file`` all name the same service (a service's socket is named
without the leading slash).
"""
from __future__ import annotations

import importlib
import re
from typing import Any

import attrs

from emos.core import control as C
from emos.core import discovery
from emos.core.discovery import KINDS, component_workers, interfaces_of, printable
from emos.core.rpc import RpcConnectionError, RpcError
from emos.errors import EmosError
from emos.msgs.registry import UnknownMessageType, resolve
from emos.transport.context import RunContext

# A module this command may import because a component named it: one of the emos package.
_EMOS_MODULE = re.compile(r"^emos(\.[A-Za-z_][A-Za-z0-9_]*)+$")


class InterfaceError(EmosError, LookupError):
    """A service or action that cannot be found, is not served now, or whose types cannot be loaded."""


@attrs.define(frozen=True)
class Interface(discovery.Interface):
    """One service or action of a component (read by :func:`emos.core.discovery.interfaces_of`),
    whose types this command may load from the module of the emos package that defines them."""

    def message_class(self, role: str) -> type:
        """The class of this interface's ``role`` type; InterfaceError says why it cannot be had."""
        type_name = self.types[role]
        try:
            return resolve(type_name)
        except UnknownMessageType:
            pass
        module = self.modules.get(role, "")
        if not _EMOS_MODULE.match(module):
            raise InterfaceError(
                f"{self.kind} {self.shown} of component {self.component!r}: its {role} type {type_name} is defined in "
                f"module {module or '?'!r}, outside the emos package; import the module that defines it with "
                f"--import MODULE (as the recipe does)") from None
        try:
            importlib.import_module(module)
            return resolve(type_name)
        except (ImportError, UnknownMessageType) as exc:
            raise InterfaceError(f"{self.kind} {self.shown} of component {self.component!r}: cannot load its {role} type "
                                 f"{type_name} from module {module}: {exc}") from None


def _a(kind: str) -> str:
    return f"an {kind}" if kind[0] in "aeiou" else f"a {kind}"


def _parse(component: str, kind: str, entries: Any) -> list[Interface]:
    return interfaces_of(component, kind, entries, Interface)


def component_interfaces(ctx: RunContext, component: str, kind: str, timeout: float) -> tuple[list[Interface], str]:
    """The ``kind`` interfaces of ``component`` and its lifecycle state; InterfaceError when the
    component does not answer."""
    try:
        info = C.call(C.control_socket(ctx, component), C.INFO, {}, timeout=timeout)
    except RpcConnectionError:
        raise InterfaceError(f"component {component!r} is not reachable in run {ctx.run_id} "
                             "(see `emos component list`; is it running?)") from None
    except (RpcError, TimeoutError) as exc:
        raise InterfaceError(f"component {component!r} did not describe itself: {exc}") from None
    if not isinstance(info, dict):
        raise InterfaceError(f"component {component!r} answered info with {type(info).__name__}, not a map")
    if "services" not in info and "actions" not in info:
        raise InterfaceError(f"component {component!r} does not list its services and actions (an EMOS older than this CLI?)")
    return _parse(component, kind, info.get(kind + "s")), printable(info.get("state", "?"), 40)


def find(ctx: RunContext, component: str, kind: str, name: str, timeout: float) -> Interface:
    """The ``kind`` called ``name`` of ``component``, served now; else InterfaceError listing what there is."""
    found, state = component_interfaces(ctx, component, kind, timeout)
    wanted = name.strip("/")
    for iface in found:
        if iface.name in (wanted, f"{component}/{wanted}"):
            if not iface.serving:
                raise InterfaceError(f"{kind} {iface.shown} of component {component!r} is not served now: the component is "
                                     f"{state}, and serves its {kind}s only while active")
            return iface
    other = "action" if kind == "service" else "service"
    elsewhere = [i for i in component_interfaces(ctx, component, other, timeout)[0] if i.name in (wanted, f"{component}/{wanted}")]
    if elsewhere:
        verb = "emos action send_goal" if other == "action" else "emos service call"
        raise InterfaceError(f"{elsewhere[0].shown} of component {component!r} is {_a(other)}, not {_a(kind)}: use `{verb}`")
    names = ", ".join(i.shown for i in found) or "none"
    raise InterfaceError(f"component {component!r} has no {kind} {name!r}; its {kind}s: {names}")


def listing(ctx: RunContext, component: str | None, kind: str, timeout: float) -> tuple[list[Interface], list[str]]:
    """The ``kind`` interfaces of ``component``, or of every component of the run when None,
    and the problems met on the way (a component that did not answer: the others are listed)."""
    if component is not None:
        return component_interfaces(ctx, component, kind, timeout)[0], []
    try:
        tree = C.call(ctx.run_dir / "supervisor.sock", C.SUPERVISOR_TREE, {}, timeout=timeout)["tree"]
    except (RpcConnectionError, RpcError, TimeoutError, KeyError, TypeError) as exc:
        raise InterfaceError(f"the supervisor of run {ctx.run_id} did not list its components: {exc}") from None
    found: list[Interface] = []
    problems: list[str] = []
    for name in component_workers(tree):
        try:
            found.extend(component_interfaces(ctx, name, kind, timeout)[0])
        except InterfaceError as exc:
            problems.append(str(exc))
    return found, problems


def print_listing(found: list[Interface], as_json: bool) -> None:
    """One line per interface, ``/name [types]`` (``ros2 service list -t``), or JSON."""
    import json

    if as_json:
        print(json.dumps([{"name": i.shown, "component": i.component, "serving": i.serving, **i.types} for i in found], indent=2))
        return
    for i in sorted(found, key=lambda i: i.name):
        roles = KINDS[i.kind]
        types = " -> ".join(i.types[r] for r in roles) if i.kind == "service" else \
            ", ".join(f"{r} {i.types[r]}" for r in roles)
        note = "" if i.serving else "  (not served now: the component is not active)"
        print(f"{i.shown} [{types}]{note}")
