"""Conditions compiled to one Python function each, for the Monitor's per-message evaluation.

The Monitor evaluates every armed event on every message of its topics. Walking the tree (or a
tree of closures) costs five or six Python calls per leaf; a generated function costs one call
per condition, reads each topic's message once and inlines the comparisons, about ten times
less per event. Same three-valued semantics as :func:`emos.events.conditions.evaluate`, which
stays the reference (a test checks they agree).

The generated source holds only names made here (``m0``, ``r3``, ``C1``...) and message field
names that are Python identifiers; every value from the tree (topic names, constants, value
sets) reaches the function through its namespace, never as source text.
"""
from __future__ import annotations

import keyword
import operator
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

Compiled = Callable[[Callable[[str], Any], "str | None"], "bool | None"]
CompiledGroup = Callable[[Callable[[str], Any], "str | None"], "tuple[bool | None, ...]"]

_CMP_OPS = {"==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}
# Values that need no conversion before a comparison (a numpy array or scalar becomes a list or a
# Python number first, as resolve_path does).
_PLAIN = frozenset({int, float, str, bool, type(None), list, tuple, bytes})


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.namespace: dict[str, Any] = {"_PLAIN": _PLAIN, "_plain": _plain}
        self.topics: dict[str, str] = {}  # topic name -> variable holding its fresh message
        self._n = 0

    def name(self, prefix: str, value: Any = None) -> str:
        self._n += 1
        var = f"{prefix}{self._n}"
        if value is not None:
            self.namespace[var] = value
        return var

    def emit(self, depth: int, line: str) -> None:
        self.lines.append("    " * depth + line)

    def message(self, topic: str) -> str:
        if topic not in self.topics:
            self.topics[topic] = f"m{len(self.topics)}"
        return self.topics[topic]


def compile_tree(tree: Mapping[str, Any]) -> Compiled:
    """One function ``(fresh, trigger) -> True | False | None`` for a condition tree."""
    from emos.events.conditions import _MISSING, _leaf, resolve_path

    w = _Writer()
    w.namespace.update(_MISSING=_MISSING, _resolve_path=resolve_path, _leaf=_leaf)
    result = _node(w, tree, 1)  # the body first: it tells which topics the header must fetch
    lines = ["def condition(fresh, trigger):"]
    lines += [f"    {var} = fresh({w.name('T', topic)})" for topic, var in w.topics.items()]
    lines += w.lines
    lines.append(f"    return {result}")
    try:
        code = compile("\n".join(lines), "<emos condition>", "exec")
    except (SyntaxError, RecursionError, MemoryError):
        # A condition too deep or too wide for Python's parser (an AND of a hundred terms nests a
        # hundred blocks): the tree walker has no such limit.
        from emos.events.conditions import evaluate

        return lambda fresh, trigger: evaluate(tree, fresh, trigger)
    exec(code, w.namespace)  # noqa: S102 - source built above from our own names only (see module doc)
    fn = w.namespace["condition"]
    fn.source = "\n".join(lines)  # for debugging: what a condition compiled to
    condition: Compiled = fn
    return condition


def compile_group(trees: Sequence[Mapping[str, Any]]) -> CompiledGroup:
    """One function ``(fresh, trigger) -> (value of each tree, ...)`` for all the conditions a
    topic's message must be checked against: one call per message instead of one per event, and
    each topic's fresh message fetched once. A tree too deep for Python's parser on its own is
    evaluated by its :func:`compile_tree` fallback from inside the group."""
    from emos.events.conditions import _MISSING, _leaf, resolve_path

    w = _Writer()
    w.namespace.update(_MISSING=_MISSING, _resolve_path=resolve_path, _leaf=_leaf)
    results: list[str] = []
    for tree in trees:
        mark = len(w.lines)
        var = _node(w, tree, 1)
        if not _parses(w.lines[mark:]):
            del w.lines[mark:]
            var = w.name("r")
            w.emit(1, f"{var} = {w.name('F', compile_tree(tree))}(fresh, trigger)")
        results.append(var)
    lines = ["def conditions(fresh, trigger):"]
    lines += [f"    {var} = fresh({w.name('T', topic)})" for topic, var in w.topics.items()]
    lines += w.lines
    lines.append(f"    return ({''.join(r + ', ' for r in results)})")
    exec(compile("\n".join(lines), "<emos conditions>", "exec"), w.namespace)  # noqa: S102 - our own names only
    fn = w.namespace["conditions"]
    fn.source = "\n".join(lines)
    conditions: CompiledGroup = fn
    return conditions


def _parses(body: list[str]) -> bool:
    try:
        compile("\n".join(["def f(fresh, trigger):", *body]), "<emos condition>", "exec")
    except (SyntaxError, RecursionError, MemoryError):
        return False
    return True


def _node(w: _Writer, tree: Mapping[str, Any], depth: int) -> str:
    """Emit code that leaves the node's value in a variable; return the variable's name."""
    op = tree["op"]
    out = w.name("r")
    if op in ("and", "or"):
        stop, other = ("False", "True") if op == "and" else ("True", "False")
        parts: list[str] = []
        indent = depth
        for arg in tree["args"]:
            var = _node(w, arg, indent)
            parts.append(var)
            w.emit(indent, f"if {var} is {stop}:")
            w.emit(indent + 1, f"{out} = {stop}")
            w.emit(indent, "else:")
            indent += 1
        unknown = " or ".join(f"{p} is None" for p in parts)
        w.emit(indent, f"{out} = None if ({unknown}) else {other}")
        return out
    if op == "not":
        inner = _node(w, tree["arg"], depth)
        w.emit(depth, f"{out} = None if {inner} is None else not {inner}")
        return out
    if op == "new_msg":
        t, m = w.name("T", tree["topic"]), w.message(tree["topic"])
        w.emit(depth, f"{out} = True if trigger == {t} else (False if {m} is not None else None)")
        return out
    m = w.message(tree["path"]["topic"])
    w.emit(depth, f"if {m} is None:")
    w.emit(depth + 1, f"{out} = None")
    w.emit(depth, "else:")
    _value(w, tree, m, depth + 1, out)
    return out


def _value(w: _Writer, tree: Mapping[str, Any], msg: str, depth: int, out: str) -> None:
    """Emit: read the leaf's path's value into ``v``, then test it into ``out`` (None when unknown)."""
    path = tree["path"]
    steps = path["steps"]
    fields = [s.get("f") for s in steps]
    simple = steps and all("f" in s and not s["map"] and s["f"].isidentifier() and not keyword.iskeyword(s["f"]) for s in steps)
    if simple:
        w.emit(depth, "try:")
        w.emit(depth + 1, f"v = {msg}.{'.'.join(fields)}")
        w.emit(depth, "except AttributeError:")  # an unset optional message on the way
        w.emit(depth + 1, "v = None")
        w.emit(depth, "if v.__class__ not in _PLAIN:")
        w.emit(depth + 1, "v = _plain(v)")
        _test(w, tree, depth, out)
        return
    p = w.name("P", path)
    w.emit(depth, f"v = _resolve_path({p}, {msg})")
    w.emit(depth, "if v is _MISSING:")
    w.emit(depth + 1, f"{out} = None")
    w.emit(depth, "else:")
    _test(w, tree, depth + 1, out)


def _test(w: _Writer, tree: Mapping[str, Any], depth: int, out: str) -> None:
    op = tree["op"]
    if op == "cmp":
        fn, c = w.name("OP", _CMP_OPS[tree["cmp"]]), w.name("C", _Box(tree["value"]))
        expr = f"bool({fn}(v, {c}.value))"
    elif op == "is_true":
        expr = "bool(v)"
    elif op == "is_false":
        expr = "not v"
    elif op in ("in", "not_in"):
        try:
            pool: Any = frozenset(tree["values"])
        except TypeError:  # unhashable values (lists): a list scan
            pool = list(tree["values"])
        expr = f"v {'in' if op == 'in' else 'not in'} {w.name('POOL', _Box(pool))}.value"
    else:
        expr = f"_leaf({w.name('LEAF', tree)}, v)"
    w.emit(depth, "try:")
    w.emit(depth + 1, f"{out} = {expr}")
    w.emit(depth, "except TypeError:")  # a value the operator cannot compare: unknown
    w.emit(depth + 1, f"{out} = None")


class _Box:
    """Holds a constant in the namespace (so that None, 0 or an empty set is stored too)."""

    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value
