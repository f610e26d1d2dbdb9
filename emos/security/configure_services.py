"""Services and action servers a component creates when it configures, found without configuring it.

Components create most of their services in ``custom_on_configure`` (``self.create_service(
f"{self.component_name}/save_map", ...)``), which runs in the component's own process at bringup:
the recipe's objects alone do not list them, yet the access rules must (a robot must be allowed
to serve them, an operator to call them).

Configuring the components in the policy tool's process would find them, at the price of running
their configure: drivers open their devices, models load, the UI lowers its process's priority.
So the names are read from the components' code instead: every method of the component's classes
(its own and its mixins', not EMOS's base classes) is parsed, and each ``self.create_service(NAME,
...)`` / ``self.create_action_server(NAME, ...)`` has its NAME evaluated by a small evaluator that
knows string constants, f-strings, ``+``, ``self.<attribute>`` and ``self.config.<field>`` of the
built component (plain values only), local variables assigned from those, and ``for`` loops over
literal lists. Every branch counts (a service created under an ``if`` may be created). A name it
cannot evaluate is reported (component, file:line, the expression) so that a person adds its key
by hand; nothing runs.

Two static declarations complete it: a component's ``action_servers()`` (the documented place for
a component to list the action servers it creates) covers its ``create_action_server`` calls, and
a ``declared_services`` attribute (names) lists services whose names only the running component
knows.
"""
from __future__ import annotations

import ast
import functools
import inspect
import linecache
import types
from dataclasses import dataclass, field
from typing import Any

from emos.errors import EmosError

__all__ = ["ConfigureServices", "configure_services"]

CREATORS = ("create_service", "create_action_server")
_PLAIN = (str, int, float, bool)
MAX_LOOP = 256  # items of a literal loop followed; more is not a naming loop


@dataclass
class ConfigureServices:
    names: list[str] = field(default_factory=list)
    unresolved: list[str] = field(default_factory=list)  # "component: file:line: expression"


class _Unknown(EmosError):
    """An expression whose value cannot be known without running the component (internal: caught
    where it is raised, and the name reported as not derived)."""


@functools.lru_cache(maxsize=256)
def _parse(filename: str) -> ast.Module | None:
    lines = linecache.getlines(filename)
    if not lines:
        return None
    try:
        return ast.parse("".join(lines), filename)
    except SyntaxError:
        return None


def _function_node(fn: Any) -> tuple[ast.FunctionDef | ast.AsyncFunctionDef, str] | None:
    code = getattr(fn, "__code__", None)
    if code is None:
        return None
    tree = _parse(code.co_filename)
    if tree is None:
        return None
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == fn.__name__:
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            if code.co_firstlineno in (first, node.lineno):
                return node, code.co_filename
    return None


def _own_functions(component: Any) -> list[Any]:
    """The methods of the component's classes that are not EMOS's own base classes."""
    out: list[Any] = []
    for cls in type(component).__mro__:
        module = getattr(cls, "__module__", "") or ""
        if cls is object or module.startswith(("emos.core.", "emos.transport.", "emos.config.")):
            continue
        for value in vars(cls).values():
            fn = value.__func__ if isinstance(value, (staticmethod, classmethod)) else value
            if inspect.isfunction(fn):
                out.append(fn)
    return out


class _Evaluator:
    def __init__(self, component: Any):
        self.component = component

    def value(self, node: ast.expr, scope: dict[str, Any]) -> Any:
        if isinstance(node, ast.Constant) and isinstance(node.value, _PLAIN):
            return node.value
        if isinstance(node, ast.JoinedStr):
            parts = []
            for part in node.values:
                if isinstance(part, ast.Constant):
                    parts.append(str(part.value))
                elif isinstance(part, ast.FormattedValue):
                    spec = self.value(part.format_spec, scope) if part.format_spec is not None else ""
                    v = self.value(part.value, scope)
                    v = {-1: v, 115: str(v), 114: repr(v), 97: ascii(v)}.get(part.conversion, v)
                    parts.append(format(v, spec))
                else:
                    raise _Unknown
            return "".join(parts)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            left, right = self.value(node.left, scope), self.value(node.right, scope)
            if isinstance(left, str) and isinstance(right, str):
                return left + right
            raise _Unknown
        if isinstance(node, ast.Name):
            if node.id in scope:
                return scope[node.id]
            raise _Unknown
        if isinstance(node, ast.Attribute):
            chain = []
            cur: ast.expr = node
            while isinstance(cur, ast.Attribute):
                chain.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name) and cur.id == "self":
                return self._attribute(list(reversed(chain)))
            raise _Unknown
        if isinstance(node, (ast.Tuple, ast.List)):
            return [self.value(e, scope) for e in node.elts]
        raise _Unknown

    def _attribute(self, chain: list[str]) -> Any:
        """``self.a`` or ``self.config.b``: plain values read from the built component, without
        calling anything (no properties: they could run code)."""
        obj: Any = self.component
        for name in chain:
            if name.startswith("__"):
                raise _Unknown
            holder = obj
            try:
                own = vars(holder)
            except TypeError:
                own = {}
            if name in own:
                obj = own[name]
            else:
                static = inspect.getattr_static(holder, name, None)
                if isinstance(static, types.MemberDescriptorType):  # a slot (attrs configs): a stored value, no code runs
                    try:
                        obj = static.__get__(holder, type(holder))
                    except AttributeError:
                        raise _Unknown from None
                elif isinstance(static, _PLAIN):  # a class constant
                    obj = static
                else:
                    raise _Unknown
        if not isinstance(obj, _PLAIN):
            raise _Unknown
        return obj


class _Finder:
    def __init__(self, component: Any, label: str):
        self.eval = _Evaluator(component)
        self.label = label
        self.found = ConfigureServices()

    def function(self, node: ast.FunctionDef | ast.AsyncFunctionDef, filename: str) -> None:
        self.filename = filename
        self.block(node.body, {})

    def block(self, body: list[ast.stmt], scope: dict[str, Any]) -> None:
        for stmt in body:
            self.statement(stmt, scope)

    def statement(self, stmt: ast.stmt, scope: dict[str, Any]) -> None:
        if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            return  # a nested definition runs only if called: its own methods are scanned as methods
        self.calls(stmt, scope)
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name):
            try:
                scope[stmt.targets[0].id] = self.eval.value(stmt.value, scope)
            except _Unknown:
                scope.pop(stmt.targets[0].id, None)
        elif isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None:
            try:
                scope[stmt.target.id] = self.eval.value(stmt.value, scope)
            except _Unknown:
                scope.pop(stmt.target.id, None)
        elif isinstance(stmt, (ast.For, ast.AsyncFor)):
            items: list[Any] | None = None
            if isinstance(stmt.target, ast.Name):
                try:
                    value = self.eval.value(stmt.iter, scope)
                    items = list(value)[:MAX_LOOP] if isinstance(value, list) else None
                except _Unknown:
                    items = None
            if items is None:
                inner = dict(scope)
                for name in _assigned(stmt.target):
                    inner.pop(name, None)
                self.block(stmt.body, inner)
            else:
                assert isinstance(stmt.target, ast.Name)
                for item in items:
                    self.block(stmt.body, {**scope, stmt.target.id: item})
            self.block(stmt.orelse, dict(scope))
        else:
            for name in ("body", "orelse", "finalbody"):
                sub = getattr(stmt, name, None)
                if isinstance(sub, list) and sub and isinstance(sub[0], ast.stmt):
                    self.block(sub, dict(scope))  # every branch: a service it may create counts
            for handler in getattr(stmt, "handlers", []) or []:
                self.block(handler.body, dict(scope))
            for case in getattr(stmt, "cases", []) or []:
                self.block(case.body, dict(scope))

    def calls(self, stmt: ast.stmt, scope: dict[str, Any]) -> None:
        """``self.create_service(NAME, ...)`` calls in the statement itself (not in its sub-blocks)."""
        for node in _own_expressions(stmt):
            for call in ast.walk(node):
                if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute) and call.func.attr in CREATORS
                        and isinstance(call.func.value, ast.Name) and call.func.value.id == "self"):
                    continue
                arg = call.args[0] if call.args else next((k.value for k in call.keywords if k.arg == "name"), None)
                if arg is None:
                    continue
                try:
                    name = self.eval.value(arg, scope)
                    if not isinstance(name, str):
                        raise _Unknown
                    self.found.names.append(name.strip("/"))
                except (_Unknown, TypeError, ValueError):
                    self.found.unresolved.append(f"{self.label}: {self.filename}:{call.lineno}: {call.func.attr}({ast.unparse(arg)}, ...)")


def _assigned(target: ast.expr) -> list[str]:
    return [n.id for n in ast.walk(target) if isinstance(n, ast.Name)]


def _own_expressions(stmt: ast.stmt) -> list[ast.AST]:
    """The parts of ``stmt`` that are not nested statements (a ``for``'s iterable, an ``if``'s test,
    an expression statement...)."""
    out: list[ast.AST] = []
    for name, value in ast.iter_fields(stmt):
        if name in ("body", "orelse", "finalbody", "handlers", "cases"):
            continue
        if isinstance(value, ast.AST):
            out.append(value)
        elif isinstance(value, list):
            out.extend(v for v in value if isinstance(v, ast.AST) and not isinstance(v, ast.stmt))
    return out


def _overrides(component: Any, method: str) -> bool:
    for cls in type(component).__mro__:
        if method in vars(cls):
            return not (getattr(cls, "__module__", "") or "").startswith("emos.core.")
    return False


def configure_services(component: Any) -> ConfigureServices:
    """The service and action names ``component``'s code creates (see the module doc), and the
    calls whose names could not be known."""
    label = f"component {getattr(component, 'component_name', '?')!r} ({type(component).__name__})"
    finder = _Finder(component, label)
    for fn in _own_functions(component):
        found = _function_node(fn)
        if found is None:
            continue
        finder.function(*found)
    out = finder.found
    declared = getattr(component, "declared_services", None) or ()
    out.names.extend(str(n).strip("/") for n in ([declared] if isinstance(declared, str) else declared))
    if _overrides(component, "action_servers"):
        # Its action servers are declared (recipe_graph takes them from action_servers()).
        out.unresolved = [u for u in out.unresolved if ": create_action_server(" not in u]
    out.names = sorted(set(out.names))
    out.unresolved = sorted(set(out.unresolved))
    return out
